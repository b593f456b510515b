"""Interop: VTK export through meshio and state-space export to python-control."""

import numpy as np
import pytest

from wingopt.dynamics import discretize


def test_vtk_round_trip(tmp_path, membrane_models, membrane_problem):
    meshio = pytest.importorskip("meshio")
    from wingopt.membrane import bubble
    from wingopt.results.vtk import export_vtk

    model = membrane_models[(13, 7)]
    z = model.project(bubble(membrane_problem.width, membrane_problem.height))
    path = export_vtk(tmp_path / "bubble.vtu", model.space, {"deflection": z}, grid=(15, 9), warp="deflection")
    mesh = meshio.read(path)
    assert mesh.points.shape == (15 * 9, 3) and mesh.cells[0].data.shape == (14 * 8, 4)
    w = mesh.point_data["deflection"]
    np.testing.assert_allclose(mesh.points[:, 2], w)
    # the centre point of the grid is the bubble's peak (1 cm)
    centre = np.argmin(np.hypot(mesh.points[:, 0] - 0.07, mesh.points[:, 1] - 0.035))
    assert w[centre] == pytest.approx(0.01, rel=1e-9)


def test_state_space_exports_to_python_control(membrane_models):
    control = pytest.importorskip("control")
    model = membrane_models[(13, 7)]
    ss = model.system.state_space()
    sys_c = ss.to_control()
    np.testing.assert_allclose(np.sort_complex(control.poles(sys_c)), np.sort_complex(ss.poles()), rtol=1e-10)
    sys_d = discretize(ss, 1e-3).to_control()
    assert sys_d.dt == 1e-3
    # DC gain of the first sensor-free output (z_0) under load coefficient 0
    np.testing.assert_allclose(
        control.dcgain(sys_c)[0, 0], np.linalg.solve(model.stiffness.toarray(), model.gram.toarray())[0, 0], rtol=1e-8
    )


def test_vtk_accepts_callables(tmp_path, membrane_models):
    meshio = pytest.importorskip("meshio")
    from wingopt.results.vtk import export_vtk

    model = membrane_models[(13, 7)]
    path = export_vtk(tmp_path / "f.vtu", model.space, {"xy": lambda x, y: x * y}, grid=(5, 3))
    mesh = meshio.read(path)
    np.testing.assert_allclose(mesh.point_data["xy"], mesh.points[:, 0] * mesh.points[:, 1])
