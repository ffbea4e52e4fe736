"""twinkit.threads.limit_threads: the native pools already loaded and the variables read by later ones."""
from __future__ import annotations

import os

import numpy as np
from threadpoolctl import threadpool_info, threadpool_limits

from twinkit.threads import BUDGET_ENV, THREAD_ENV, limit_threads


def test_limit_threads_sets_the_loaded_pools_and_the_environment(monkeypatch):
    for var in (*THREAD_ENV, BUDGET_ENV):
        monkeypatch.setenv(var, "1")
    np.dot(np.ones((4, 4)), np.ones((4, 4)))  # numpy's BLAS is loaded
    with threadpool_limits(limits=None):  # put the pools back as they were after the test
        pools = threadpool_info()
        assert pools, "numpy's BLAS should be a loaded pool"
        for n in (2, 3):
            limit_threads(n)
            assert {p["num_threads"] for p in threadpool_info()} == {n}, threadpool_info()
            assert all(os.environ[v] == str(n) for v in (*THREAD_ENV, BUDGET_ENV))
        limit_threads(0)  # never below one thread
        assert {p["num_threads"] for p in threadpool_info()} == {1}
