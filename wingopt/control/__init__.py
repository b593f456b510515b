"""Control of the plate wing: LQR/LQG baseline and morphing QPs."""

from wingopt.control.lqr import dlqe, dlqr, lqe, lqr

__all__ = ["lqr", "dlqr", "lqe", "dlqe"]
