"""The probes benchmarks time and watch the package through (tendon_taichi/probes.py):
off, a probed function is itself; timers only time; wrappers nest and come off."""

import numpy as np
import pytest
import scipy.sparse as sp

from tendon_taichi import probes
from tendon_taichi.solve.cholesky import LDL


@probes.probe("test.twice")
def twice(x):
    return 2 * x


def test_a_probe_calls_its_function_and_keeps_its_name():
    assert twice(3) == 6 and twice.__name__ == "twice" and twice.probe == "test.twice"
    assert probes.PROBES["test.twice"] == {f"{__name__}.twice"}


def test_wrappers_nest_the_later_outside_and_come_off():
    with probes.around("test.twice", lambda call, x: call(x) + 1):
        with probes.around("test.twice", lambda call, x: 10 * call(x)):
            assert twice(3) == 70
        assert twice(3) == 7
    assert twice(3) == 6 and not probes._listening


def test_an_unknown_probe_is_an_error():
    with pytest.raises(KeyError, match="no probe 'test.nothing'"):
        with probes.around("test.nothing", lambda call: None):
            pass


def test_timers_count_and_time_the_cholesky_and_change_no_bit():
    n = 40
    A = sp.random(n, n, 0.1, random_state=0)
    A = (A + A.T + 10 * sp.eye(n)).tocsc()
    b = np.arange(n, dtype=float)
    ldl = LDL(A.indptr, A.indices, n)
    assert ldl.factor(A.data)
    plain = ldl.solve(b)
    with probes.timers("factor", "solves", "test.twice") as clock:
        assert ldl.factor(A.data)
        timed = [ldl.solve(b), ldl.solve(b)]
    assert all(np.array_equal(plain, x) for x in timed)
    assert (clock["factor"].calls, clock["solves"].calls, clock["test.twice"].calls) == (1, 2, 0)
    assert clock["factor"].seconds > 0 and clock["solves"].seconds > 0
    ldl.solve(b)
    assert clock["solves"].calls == 2  # off after the block
