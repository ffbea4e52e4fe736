"""Points linked into groups within a distance (twinkit.surface.linked)."""
from __future__ import annotations

import numpy as np

from twinkit.surface.linked import linked_groups


def test_points_closer_than_the_link_are_one_group_and_chains_link_too():
    # a chain of points 0.3 m apart (one group though its ends lie 1.2 m apart), a pair 5 m away, a lone point
    chain = np.c_[np.arange(5) * 0.3, np.zeros(5)]
    pair = np.array([[5.0, 0.0], [5.2, 0.0]])
    lone = np.array([[0.0, 3.0]])
    n, group = linked_groups(np.vstack([chain, pair, lone]), 0.35)
    assert n == 3
    assert len(set(group[:5])) == 1 and group[5] == group[6] and len({group[0], group[5], group[7]}) == 3
    n, group = linked_groups(np.vstack([chain, pair, lone]), 0.25)  # the chain breaks into its points, the pair not
    assert n == 7 and group[5] == group[6]
    assert linked_groups(np.zeros((0, 3)), 1.0)[0] == 0
