"""Reproduce Tables 6.2/6.3 on the three seed meshes; print deviations and build times.

.venv/bin/python benchmarks/membrane_tables.py
"""

import time

import numpy as np

from wingopt.membrane import MembraneModel
from wingopt.problem import load_problem

TABLE_6_2 = {
    (13, 7): [82.140658289, 103.90063548, 132.44827162, 151.46455282],
    (25, 13): [82.14063341, 103.90059613, 132.44779727, 151.45989864],
    (49, 25): [82.14063306, 103.90059557, 132.44779115, 151.45984442],
}
TABLE_6_3 = {
    (13, 7): [-31.919407 + 515.116976j, -39.910341 + 651.605852j, -53.228785 + 830.492986j,
              -63.885917 + 949.533112j, -71.876851 + 1029.731486j],
    (25, 13): [-31.919399 + 515.116819j, -39.910325 + 651.605605j, -53.228537 + 830.490015j,
               -63.883134 + 949.503990j, -71.874060 + 1029.704576j],
    (49, 25): [-31.919399 + 515.116817j, -39.910325 + 651.605601j, -53.228534 + 830.489977j,
               -63.883102 + 949.503651j, -71.874027 + 1029.704263j],
}  # fmt: skip


def main() -> None:
    problem = load_problem("membrane")
    print(f"{'mesh':>6} {'dofs':>5} {'build s':>8} {'modes s':>8} {'max rel dev 6.2':>16} {'max abs dev 6.3':>16}")
    for nodes, ref in TABLE_6_2.items():
        t0 = time.perf_counter()
        model = MembraneModel.from_problem(problem, nodes)
        t1 = time.perf_counter()
        f = model.frequencies_hz(4)
        s = model.eigenvalues(5)
        t2 = time.perf_counter()
        dev_f = np.max(np.abs(f - ref) / np.asarray(ref))
        ref3 = np.asarray(TABLE_6_3[nodes])
        dev_s = max(np.abs(s.real - ref3.real).max(), np.abs(s.imag - ref3.imag).max())
        print(f"{nodes[0]:>3}x{nodes[1]:<2} {model.n:>5} {t1 - t0:>8.3f} {t2 - t1:>8.3f} {dev_f:>16.2e} {dev_s:>16.2e}")


if __name__ == "__main__":
    main()
