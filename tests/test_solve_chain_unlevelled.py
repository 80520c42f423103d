"""A policy's chain solved with layers in which a component has no level (-1, as the
analysis lifts the quotient's levels only to the components inside it) is decomposed by
itself: the values equal a dense solve of ``x = b + Q x`` written here."""

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.evaluation import _solve_transient


def test_unlevelled_component_decomposed_here() -> None:
    # 0 -> 1 -> 2 (a two-state loop 2<->3 leaking out), each step half lost
    q = np.zeros((4, 4))
    q[0, 1] = 0.5
    q[1, 2] = 0.5
    q[2, 3] = 0.5
    q[3, 2] = 0.25
    b = np.array([0.1, 0.2, 0.3, 0.4])
    expected = np.linalg.solve(np.eye(4) - q, b)
    # components 0:{0} 1:{1} 2:{2,3}; component 0 has no level, the others wrong on purpose
    comp = np.array([0, 1, 2, 2])
    level = np.array([-1, 0, 0])
    got = _solve_transient(sp.csr_array(q), b, "auto", (comp, level))
    np.testing.assert_allclose(got, expected, rtol=1e-14)
    np.testing.assert_allclose(_solve_transient(sp.csr_array(q), b, "auto"), expected,
                               rtol=1e-14)
