"""What every modal membrane shares: the modes, the linear (prestress) part, sensors and input.

On a tensor-product spline space ``M^-1 Gx`` and ``M^-1 Gy`` commute (``Gx = ∫ phi_x phi_x^T``,
``Gy = ∫ phi_y phi_y^T``), so the modes of ``(Gx + c Gy, M)`` for a generic ``c`` are tensor
products that diagonalise ``Gx`` and ``Gy`` *simultaneously* (``kx_j``, ``ky_j``). For any pair of
prestrains the linear membrane is then ``m`` independent damped oscillators

    q_j'' + c_j q_j' + (Tx kx_j + Ty ky_j) q_j = (Phi^T M f)_j,
    Tx = C (ex + nu ey),  Ty = C (ey + nu ex),  c_j = d (gamma / (rho h) + eta (Tx0 kx_j + Ty0 ky_j))

with ``d`` a damping factor (spec §2 at ``d = 1`` and the file's prestrain). The nonlinear models
(:class:`~wingopt.membrane.modal.berger.BergerModal`, :class:`~wingopt.membrane.modal.fvk.FvKModal`)
add the deflection's own stiffening to this linear part; with ``nonlinear=False`` they are this
linear model exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from wingopt.errors import InputError, SolverError
from wingopt.fe import DX, DY, VALUE, assemble, separable
from wingopt.membrane.modal.kernels import (
    SETTLE_TOL,
    SETTLE_TOL_TANGENT,
    step_tangent,
    tangent_substeps,
    trajectory,
    trajectory_substeps,
)
from wingopt.membrane.modal.kernels import tangent as record_tangent
from wingopt.membrane.modal.tangent import ForceTangent, settled_from
from wingopt.membrane.model import MembraneModel
from wingopt.membrane.parameters import MembraneParameters, membrane_stiffness

__all__ = ["ModalMembrane"]

_SPLIT = 1.0 + np.sqrt(2.0) / 10.0
"""Weight of ``Gy`` in the pencil whose modes diagonalise ``Gx`` and ``Gy`` (breaks the degeneracies
of the rectangle, e.g. (2,2) and (4,1) at W = 2L, without changing the eigenvectors)."""


@dataclass(frozen=True, eq=False)
class ModalMembrane:
    """The lowest ``m`` tensor-product modes of a membrane model, integrated at ``dt``.

    Attributes
    ----------
    model : MembraneModel
    shapes : ndarray ``(n, m)``, ``rho h M``-orthonormal
    kx, ky : ndarray ``(m,)``
        ``phi_j^T Gx phi_j`` and ``phi_j^T Gy phi_j`` (modal stiffness per unit tension).
    sensor_matrices : ndarray ``(p, m, m)``
    input_matrix : ndarray ``(m, n)``
        ``Phi^T M``: modal force of load coefficients ``f`` (``p = M f``).
    dt : float
        Sample period; ``substeps`` integration steps per sample.
    """

    model: MembraneModel
    shapes: np.ndarray
    kx: np.ndarray
    ky: np.ndarray
    sensor_matrices: np.ndarray
    input_matrix: np.ndarray
    dt: float
    substeps: int = 1

    @staticmethod
    def modal_fields(model: MembraneModel, modes: int, dt: float | None, substeps: int) -> dict:
        """The shared fields of a modal model of ``model`` (the ``modes`` lowest at the nominal prestress)."""
        n = model.n
        if not (isinstance(modes, (int, np.integer)) and 1 <= modes <= n):
            raise InputError(f"modes = {modes!r}: expected an integer in 1..{n} for this mesh")
        if not (isinstance(substeps, (int, np.integer)) and substeps >= 1):
            raise InputError(f"substeps = {substeps!r}: expected an integer >= 1")
        space = model.space
        gx = assemble(space, separable((1.0, DX, DX))).toarray()
        gy = assemble(space, separable((1.0, DY, DY))).toarray()
        mass = model.problem.material.areal_density * assemble(space, separable((1.0, VALUE, VALUE))).toarray()
        _, vecs = sla.eigh(gx + _SPLIT * gy, mass)
        kx = np.einsum("ij,ik,kj->j", vecs, gx, vecs)
        ky = np.einsum("ij,ik,kj->j", vecs, gy, vecs)
        order = np.argsort(kx + ky)[:modes]
        Phi, kx, ky = vecs[:, order], kx[order], ky[order]
        off = np.abs(Phi.T @ gx @ Phi - np.diag(kx)).max() / kx.max()
        if off > 1e-6:  # pragma: no cover - holds for every tensor-product spline space
            raise InputError(f"modal membrane: Gx is not diagonal in the modes ({off:.1e})")
        Chat = np.stack([Phi.T @ (C @ Phi) for C in model.sensors.matrices])
        B = np.asarray((model.gram @ Phi).T)
        dt = model.problem.identification.dt if dt is None else float(dt)
        if not (np.isfinite(dt) and dt > 0):
            raise InputError(f"dt = {dt!r}: expected a positive sample period (s)")
        return dict(
            model=model, shapes=Phi, kx=kx, ky=ky, sensor_matrices=Chat, input_matrix=B, dt=dt, substeps=int(substeps)
        )

    # -- sizes and constants ---------------------------------------------------------------
    @property
    def m(self) -> int:
        return self.kx.size

    @property
    def p(self) -> int:
        return self.sensor_matrices.shape[0]

    @property
    def area(self) -> float:
        return self.model.problem.width * self.model.problem.height

    @property
    def stiffness_c(self) -> float:
        """``C = E h / (1 - nu^2)`` (N/m)."""
        return membrane_stiffness(self.model.problem.material)

    @property
    def prestrain(self) -> float:
        return self.model.problem.material.prestrain

    @property
    def nominal(self) -> MembraneParameters:
        """The problem file's parameters (isotropic prestrain, damping factor 1)."""
        return MembraneParameters.nominal(self.model.problem)

    def omega(self, ex: float | None = None, ey: float | None = None) -> np.ndarray:
        """Linear (small-deflection) circular frequencies at prestrains ``ex, ey`` (default: the file's)."""
        tx, ty = self.tensions(self.prestrain if ex is None else ex, self.prestrain if ey is None else ey)
        return np.sqrt(tx * self.kx + ty * self.ky)

    def tensions(self, ex, ey):
        """``(Tx, Ty)`` of total strains ``ex, ey``."""
        nu = self.model.problem.material.poisson_ratio
        C = self.stiffness_c
        return C * (ex + nu * ey), C * (ey + nu * ex)

    def stretch(self, q):
        """Mean stretches ``(sx, sy)`` of modal displacements ``q`` (last axis the modes)."""
        two_a = 2.0 * self.area
        return (q * q) @ self.kx / two_a, (q * q) @ self.ky / two_a

    def linear_terms(self, ex, ey, damping, dpar=None, substeps: int | None = None):
        """The parameter-dependent linear part of a sub-step and its tangents.

        Returns ``h`` (sub-step), the prestress stiffness ``k0`` and its tangent ``dk0`` (P, m), half
        the damping ``a`` and ``da`` (P, m), and ``e = exp(-a h)``; ``dpar`` is ``(3, P)``, the seeds of
        ``ex, ey, damping`` (default none); ``substeps`` per sample (default the model's).
        """
        mat = self.model.problem.material
        nu, C, h = mat.poisson_ratio, self.stiffness_c, self.dt / (self.substeps if substeps is None else substeps)
        k0 = C * ((ex + nu * ey) * self.kx + (ey + nu * ex) * self.ky)
        k0x, k0y = C * (self.kx + nu * self.ky), C * (self.ky + nu * self.kx)
        visc = mat.viscous / mat.areal_density + mat.kelvin_voigt * k0
        a = 0.5 * damping * visc
        dex, dey, dd = np.zeros((3, 0)) if dpar is None else dpar
        dk0 = np.outer(dex, k0x) + np.outer(dey, k0y)
        da = 0.5 * (np.outer(dd, visc) + damping * mat.kelvin_voigt * dk0)
        return h, k0, dk0, a, da, np.exp(-a * h)

    # -- fields and sensors ----------------------------------------------------------------
    def outputs(self, Q: np.ndarray) -> np.ndarray:
        """Sensor outputs ``(N, p)`` of real modal displacements ``Q`` ``(N, m)``."""
        return np.einsum("kpi,ki->kp", self.sensor_products(Q), Q)

    def sensor_products(self, Q: np.ndarray) -> np.ndarray:
        """``C_p q_k`` ``(N, p, m)`` for modal displacements ``Q`` ``(N, m)`` (one GEMM)."""
        p, m = self.p, self.m
        return (Q @ self.sensor_matrices.reshape(p * m, m).T).reshape(Q.shape[0], p, m)

    def deflection(self, q: np.ndarray) -> np.ndarray:
        """Deflection coefficients ``Phi q``."""
        return np.asarray(q) @ self.shapes.T

    def to_modal(self, z: np.ndarray) -> np.ndarray:
        """Modal coordinates of deflection coefficients (mass-orthonormal projection)."""
        return self.shapes.T @ (self.model.mass @ z)

    def modal_force(self, f: np.ndarray) -> np.ndarray:
        """Modal force ``Phi^T M f`` of load coefficients ``f`` (``(n,)`` or ``(N, n)``)."""
        return np.asarray(f) @ self.input_matrix.T

    # -- the forward-model protocol (:mod:`wingopt.membrane.forward`) ------------------------
    settles = False
    """Whether a record under a force constant from some sample on stops once it has settled
    (:data:`~.kernels.SETTLE_TOL`); complex runs never do (the derivative settles on its own scale)."""

    def force_law(self, nonlinear: bool = True, dtype=float) -> tuple:  # pragma: no cover
        """The compiled loop's force law (:mod:`.laws`), its arrays in ``dtype`` (subclasses)."""
        raise NotImplementedError

    def simulate(self, q0, v0, forces, ex, ey, damping=1.0, nonlinear: bool = True, every_substep: bool = False):
        """Modal displacements at every sample (or displacements and velocities at every sub-step).

        Parameters
        ----------
        q0, v0 : array ``(..., m)``
            Initial displacement and velocity (leading batch axes allowed; complex allowed).
        forces : array ``(N, ..., m)``
            Modal force held over each sample interval.
        ex, ey, damping : array ``(...)`` or float
            Prestrains and damping factor.
        nonlinear : bool
            ``False`` leaves the deflection's own stiffening out (the linear membrane).
        every_substep : bool
            The states at every sub-step, ``Q`` and the modal velocities ``V`` ``(N substeps + 1,
            ..., m)`` (sample ``n`` at row ``n substeps``; a DAQ filter run on the outputs' Hermite
            interpolant, :mod:`wingopt.measurements.analog_filter`).

        Returns
        -------
        Q : array ``(N + 1, ..., m)``; each trajectory of a batch by the compiled loop
        """
        forces = np.asarray(forces)
        N, m = forces.shape[0], self.m
        dtype = np.result_type(q0, v0, forces, ex, ey, damping, float)
        shape = np.broadcast_shapes(
            np.shape(q0)[:-1], np.shape(v0)[:-1], forces.shape[1:-1], np.shape(ex), np.shape(ey), np.shape(damping)
        )
        q0, v0 = np.broadcast_to(q0, shape + (m,)), np.broadcast_to(v0, shape + (m,))
        lead = (1,) * (len(shape) - forces.ndim + 2)  # the force's batch axes are the trailing ones
        F = np.broadcast_to(forces.reshape((N,) + lead + forces.shape[1:]), (N,) + shape + (m,))
        ex, ey, damping = (np.broadcast_to(np.asarray(x, dtype), shape) for x in (ex, ey, damping))
        Q = np.empty((N * (self.substeps if every_substep else 1) + 1,) + shape + (m,), dtype)
        V = np.empty_like(Q) if every_substep else None
        law = self.force_law(nonlinear, dtype)
        real = dtype == np.float64
        with np.errstate(over="ignore", invalid="ignore"):  # a diverging trial step gives non-finite costs
            for i in np.ndindex(shape):
                h, k0, _, a, _, e = self.linear_terms(ex[i], ey[i], damping[i])
                Fi = np.ascontiguousarray(F[(slice(None),) + i], dtype)
                settle = settled_from(Fi) if real and self.settles else N
                q, v = np.array(q0[i], dtype), np.array(v0[i], dtype)
                at = (slice(None),) + i
                if V is None:
                    Q[at] = trajectory(q, v, Fi, k0, a, e, h, self.substeps, law, settle, SETTLE_TOL)
                else:
                    Q[at], V[at] = trajectory_substeps(q, v, Fi, k0, a, e, h, self.substeps, law, settle, SETTLE_TOL)
        return Q if V is None else (Q, V)

    def simulate_tangent(
        self, q0, v0, forces, ex, ey, damping, dq0, dv0, dpar, dforces, nonlinear: bool = True, every_substep=False
    ):
        """Trajectory ``(N+1, m)`` and its exact tangents ``(N+1, P, m)`` (real arguments); with
        ``every_substep`` (a :class:`~.tangent.ForceTangent` only) at every sub-step, ``(N substeps
        + 1, ...)``, and the modal velocities and their tangents beside them: ``Q, dQ, V, dV``.

        Parameters
        ----------
        q0, v0 : ``(m,)``; forces : ``(N, m)``; ex, ey, damping : float
        dq0, dv0 : ``(P, m)`` seeds of the initial state
        dpar : ``(3, P)`` seeds of ``ex, ey, damping``
        dforces : :class:`~.tangent.ForceTangent` (the whole record in one compiled call), or any
            callable ``k -> (P, m)``: the tangent of the force held over interval ``k`` (sample by sample)
        """
        h, k0, dk0, a, da, e = self.linear_terms(ex, ey, damping, dpar)
        mm = lambda x: np.ascontiguousarray(np.asarray(x, float).T)  # noqa: E731 - mode-major for the kernel
        q, v, forces = np.asarray(q0, float), np.asarray(v0, float), np.ascontiguousarray(forces, float)
        N = forces.shape[0]
        # the loop's constants: the linear part (tangents mode-major) and the force law
        terms = (k0, mm(dk0), a, mm(da), e, h, self.substeps, self.force_law(nonlinear))
        if isinstance(dforces, ForceTangent):
            f = dforces
            settle = settled_from(forces, f.amp, f.hats) if self.settles else N
            amp, base, hats = np.asarray(f.amp, float), mm(f.base), np.ascontiguousarray(f.hats, float)
            force = (amp, base, hats, int(f.g0), np.asarray(f.fc, float))
            tols = (SETTLE_TOL, SETTLE_TOL_TANGENT)
            run = tangent_substeps if every_substep else record_tangent
            return _major(run(q, v, forces, *terms, mm(dq0), mm(dv0), *force, settle, tols))
        if every_substep:
            raise InputError("simulate_tangent: every_substep needs the force's tangent as a ForceTangent")
        dq, dv = mm(dq0), mm(dv0)
        Q, dQ = np.empty((N + 1, self.m)), np.empty((N + 1,) + dq.shape)
        Q[0], dQ[0] = q, dq
        for j in range(N):
            q, v, dq, dv = step_tangent(q, v, forces[j], mm(dforces(j)), *terms, dq, dv)
            Q[j + 1], dQ[j + 1] = q, dq
        return Q, dQ.transpose(0, 2, 1)

    def internal_force(self, q: np.ndarray, ex: float, ey: float, nonlinear: bool = True):  # pragma: no cover
        """Modal internal force ``k0 q + N(q)`` and its Jacobian at ``q`` (subclasses)."""
        raise NotImplementedError

    def equilibrium(
        self, u: np.ndarray, params: MembraneParameters | None = None, nonlinear: bool = True
    ) -> np.ndarray:
        """Static modal displacements under the modal force ``u``: Newton from the linear solution,
        each step halved until the residual falls (the internal force is a potential's gradient)."""
        par = self.nominal if params is None else params
        u = np.asarray(u, dtype=float)
        k0 = self.omega(par.eps0_x, par.eps0_y) ** 2
        q = u / k0
        scale = max(np.linalg.norm(u), 1e-300)
        for _ in range(100):
            F, J = self.internal_force(q, par.eps0_x, par.eps0_y, nonlinear)
            r = F - u
            res = np.linalg.norm(r)
            if res <= 1e-12 * scale:
                return q
            step = -np.linalg.solve(J, r)
            t = 1.0
            while t > 1e-6:
                Ft, _ = self.internal_force(q + t * step, par.eps0_x, par.eps0_y, nonlinear)
                if np.linalg.norm(Ft - u) < res:
                    break
                t *= 0.5
            q = q + t * step
        raise SolverError(
            f"{type(self).__name__} static solve", f"residual {res / scale:.1e} after 100 steps", "reduce the load"
        )

    def record(
        self, load, t_end: float, z0=None, v0=None, params: MembraneParameters | None = None, nonlinear: bool = True
    ):
        """Deflection coefficients ``(N + 1, n)`` every ``dt`` under load coefficients held per sample.

        ``load``: coefficients ``(n,)``, a history ``(N, n)`` or a callable ``t -> (n,)``; ``z0, v0``
        deflection and velocity coefficients (default rest); ``params`` default: the file's.
        """
        par = self.nominal if params is None else params
        if par.viscous_scale != par.kelvin_voigt_scale:
            raise InputError(
                f"{type(self).__name__}: one damping factor scales both terms; got viscous x{par.viscous_scale:g}, "
                f"Kelvin-Voigt x{par.kelvin_voigt_scale:g}"
            )
        steps = int(round(t_end / self.dt))
        if steps < 1:
            raise InputError(f"t_end = {t_end!r}: shorter than one sample (dt = {self.dt:g} s)")
        n = self.model.n
        if callable(load):
            F = np.stack([np.asarray(load(k * self.dt), float) for k in range(steps)])
        else:
            F = np.broadcast_to(np.asarray(load, float), (steps, n))
        if F.shape != (steps, n):
            raise InputError(f"load: shape {F.shape}, expected ({n},), ({steps}, {n}) or a callable t -> ({n},)")
        q0 = np.zeros(self.m) if z0 is None else self.to_modal(np.asarray(z0, float))
        qv = np.zeros(self.m) if v0 is None else self.to_modal(np.asarray(v0, float))
        Q = self.simulate(q0, qv, self.modal_force(F), par.eps0_x, par.eps0_y, par.viscous_scale, nonlinear)
        return self.deflection(Q)


def _major(out: tuple) -> tuple:
    """The compiled loop's ``(Q, dQ[, V, dV])`` with the tangents direction-major ``(N+1, P, m)``."""
    return tuple(x if x.ndim == 2 else x.transpose(0, 2, 1) for x in out)
