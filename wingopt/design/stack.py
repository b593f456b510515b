"""Per-candidate information matrices held packed: the design's memory.

A design holds, for each of ``N`` candidates and ``J`` nominal loads, the ``d x d`` information
of the first window and of the whole record: ``N J 2 d^2`` numbers (2331 x 12 x 2 x 64^2 on the
default membrane: 1.8 GB in float64). The matrices are symmetric, so :class:`InfoStack` keeps
only their upper triangles (``d (d + 1) / 2`` numbers each, half the memory) and unpacks the
candidates a criterion asks for (``stack[index]``: dense, as an array would give them). Sums of
candidates are sums of their triangles, so a layout's information is the same numbers as with
dense storage (the matrices are mirrored exactly instead of as computed).

:class:`TransformedStack` is a second whitening of one segment of a stack, applied when asked
(``T^T F T``): the linear criteria's view of the risk's information, without a second copy.
"""

from __future__ import annotations

import ctypes
import gc
import logging
import tempfile
from contextlib import contextmanager

import numpy as np

log = logging.getLogger(__name__)

__all__ = ["InfoStack", "TransformedStack", "information_stack", "dense_stack"]


def _release_freed_memory() -> None:
    """Hand the heap freed by the solver back to the system (glibc keeps freed small blocks in its
    arenas, so the process would hold them beside the matrices it reads back); elsewhere a no-op."""
    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError, TypeError):  # not glibc
        pass


class InfoStack:
    """Symmetric matrices ``(N, *lead, d, d)`` stored as upper triangles ``(N, *lead, d (d+1)/2)``.

    Parameters
    ----------
    packed : ndarray
        The upper triangles (row-major, :func:`numpy.triu_indices` order).
    d : int
        Matrix size.
    """

    def __init__(self, packed: np.ndarray, d: int) -> None:
        self.packed = packed
        self._shape = packed.shape  # kept while the matrices are spilled to disk
        self.d = int(d)
        self._iu = np.triu_indices(self.d)
        self.scale: np.ndarray | None = None  # the whitening of the state block, when built here

    @classmethod
    def empty(cls, n: int, lead: tuple[int, ...], d: int) -> InfoStack:
        """A stack of ``n`` candidates to fill with :meth:`put`."""
        return cls(np.empty((n, *lead, d * (d + 1) // 2)), d)

    @property
    def shape(self) -> tuple[int, ...]:
        return (*self._shape[:-1], self.d, self.d)

    def __len__(self) -> int:
        return self._shape[0]

    @property
    def nbytes(self) -> int:
        return int(np.prod(self._shape)) * 8

    def put(self, index, dense: np.ndarray) -> None:
        """Store dense symmetric matrices (their upper triangles) at first-axis ``index``."""
        self.packed[index] = dense[..., self._iu[0], self._iu[1]]

    def unpack(self, packed: np.ndarray) -> np.ndarray:
        """Dense symmetric matrices of upper triangles ``packed`` ``(..., p)``."""
        out = np.empty((*packed.shape[:-1], self.d, self.d))
        i, j = self._iu
        out[..., i, j] = packed
        out[..., j, i] = packed
        return out

    def __getitem__(self, index) -> np.ndarray:
        """Dense matrices of the candidates ``index`` (an int, a slice or an index array)."""
        return self.unpack(self.packed[index])

    def sum(self, index) -> np.ndarray:
        """Dense sum over the candidates ``index``: a layout's information."""
        return self.unpack(self.packed[np.asarray(index, dtype=int)].sum(axis=0))

    def mean(self) -> np.ndarray:
        """Dense mean over all candidates."""
        return self.unpack(self.packed.mean(axis=0))

    @contextmanager
    def spilled(self):
        """Within the block the matrices are in a temporary file, not in memory (the relaxation's
        solver builds its own large copy of the problem meanwhile); they are read back after it.
        Where the file cannot be written they stay in memory."""
        shape = self.packed.shape
        with tempfile.TemporaryFile(prefix="wingopt-design-") as f:
            try:
                self.packed.tofile(f)
            except OSError as exc:  # a full or read-only temporary directory: keep them in memory
                log.info("design: the candidate information stays in memory (%s)", exc)
                yield
                return
            self.packed = None
            try:
                yield
            finally:
                # The solver's problem data sit in reference cycles (expression trees): free them
                # before the matrices come back, or both are held at once.
                gc.collect()
                _release_freed_memory()
                f.seek(0)
                self.packed = np.fromfile(f, dtype=float).reshape(shape)

    def take(self, index) -> InfoStack:
        """A new stack of the candidates ``index`` (copied)."""
        return InfoStack(self.packed[np.asarray(index, dtype=int)], self.d)


class TransformedStack:
    """``T^T F T`` of the segment ``segment`` of an :class:`InfoStack` ``(N, J, S, d, d)``, computed when asked.

    Reads like a dense ``(N, J, d, d)`` array indexed on its first axis.
    """

    def __init__(self, base: InfoStack, segment: int, transform: np.ndarray) -> None:
        self.base = base
        self.segment = int(segment)
        self.transform = np.asarray(transform, dtype=float)

    @property
    def shape(self) -> tuple[int, ...]:
        n, j = self.base.shape[:2]
        d = self.transform.shape[1]
        return (n, j, d, d)

    def __len__(self) -> int:
        return len(self.base)

    def _apply(self, F: np.ndarray) -> np.ndarray:
        T = self.transform
        return T.T @ F @ T

    def __getitem__(self, index) -> np.ndarray:
        return self._apply(self.base.unpack(self.base.packed[index][..., self.segment, :]))

    def sum(self, index) -> np.ndarray:
        packed = self.base.packed[np.asarray(index, dtype=int)][..., self.segment, :].sum(axis=0)
        return self._apply(self.base.unpack(packed))


def information_stack(sens, chat: np.ndarray, modal_loads, q0, scale, chunk: int = 32, progress=None) -> InfoStack:
    """The risk's information ``(N, J, 2, d, d)`` (first window, whole record), its state block
    whitened by ``scale`` (``S F S``, the state prior's std then ones), filled chunk by chunk:
    only the packed stack and one chunk's dense matrices are ever held (a chunk's Jacobians are
    ``chunk x samples x d`` numbers: 16 MB at 32 candidates of 1001 samples).

    ``modal_loads``: the modal load ``u`` of each nominal response; ``progress(fraction)`` is
    called after each chunk.
    """
    N, J, d = len(chat), len(modal_loads), sens.dim
    S = np.asarray(scale, dtype=float)
    W = S[:, None] * S[None, :]
    stack = InfoStack.empty(N, (J, 2), d)
    stack.scale = S
    for j, u in enumerate(modal_loads):
        for a in range(0, N, chunk):
            inf = sens.information(chat[a : a + chunk], u, q0, chunk=chunk)
            stack.put((slice(a, a + chunk), j), np.stack([inf.window, inf.total], axis=1) * W)
            if progress is not None:
                progress((j + min(a + chunk, N) / N) / J)
    return stack


def dense_stack(infos, scale) -> InfoStack:
    """:func:`information_stack` of information already computed (a list of ``SegmentInformation``)."""
    S = np.asarray(scale, dtype=float)
    info = np.stack([np.stack([inf.window, inf.total], axis=1) for inf in infos], axis=1)
    info *= S[:, None] * S[None, :]
    stack = InfoStack.empty(info.shape[0], info.shape[1:3], info.shape[-1])
    stack.put(slice(None), info)
    stack.scale = S
    return stack
