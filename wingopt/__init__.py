"""wingopt: control and estimation of flexible wings.

Data flow: mesh/basis (:mod:`wingopt.fe`) -> FE operators (:mod:`wingopt.membrane`,
:mod:`wingopt.plate`) -> state space (:mod:`wingopt.dynamics`) -> control QP
(:mod:`wingopt.control`) or estimation (:mod:`wingopt.estimation`) -> results.
"""

__version__ = "0.1.0"
