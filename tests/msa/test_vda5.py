"""The VDA 5 / ISO 22514-7 budget by hand: each component, the max rule of resolution
and repeatability, U = 2 u, Q = 2 U / T against 15 % and 30 %, the refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest
from msa_data import AIAG  # tests/msa is on the path

from piecs_bayes.errors import InputError
from piecs_bayes.msa import MsaSettings, Reference, gauge_rr, type1_study, uncertainty_budget

REF = Reference(40.0, 0.0004, 2.0)  # u_CAL = 0.2 um
T = 0.020


def _type1(s=0.0003, bias=0.0003, resolution=1e-4):
    z = np.random.default_rng(0).normal(size=50)
    x = 40.0 + bias + s * (z - z.mean()) / z.std(ddof=1)
    return type1_study(x, reference=REF, tolerance=T, resolution=resolution)


def _u(budget):
    return {c.symbol: c for c in budget.components}


def test_the_measuring_system_by_hand():
    b = uncertainty_budget(_type1(), system={"linearity": 0.0001})
    u = _u(b)
    assert u["u_CAL"].u == pytest.approx(0.0002)
    assert u["u_RE"].u == pytest.approx(1e-4 / math.sqrt(12))
    assert u["u_EVR"].u == pytest.approx(0.0003)
    assert u["u_BI"].u == pytest.approx(0.0003 / math.sqrt(3))
    assert u["u_LIN"].u == 0.0001 and u["u_LIN"].origin == "given"
    assert not u["u_RE"].in_ms and u["u_EVR"].in_ms  # max rule: s > RE / sqrt 12
    u_ms = math.sqrt(4e-8 + 9e-8 + 3e-8 + 1e-8)
    assert b.u_ms == pytest.approx(u_ms, rel=1e-12)
    assert b.U_ms == pytest.approx(2 * u_ms) and b.q_ms == pytest.approx(4 * u_ms / T)  # 8.2 %
    assert b.q_ms_ok and b.verdict == "capable" and b.u_mp is None and b.q_mp is None
    assert b.t_min_ms == pytest.approx(4 * u_ms / 0.15)


def test_resolution_counts_when_it_is_the_larger():
    b = uncertainty_budget(_type1(resolution=0.002))
    u = _u(b)
    assert u["u_RE"].in_ms and not u["u_EVR"].in_ms
    assert b.u_ms == pytest.approx(math.sqrt(4e-8 + 0.002**2 / 12 + 3e-8))
    both = uncertainty_budget(
        _type1(resolution=0.002), settings=MsaSettings(resolution_rule="both")
    )
    assert both.u_ms == pytest.approx(math.sqrt(4e-8 + 0.002**2 / 12 + 9e-8 + 3e-8))


def test_a_corrected_bias_is_not_counted():
    b = uncertainty_budget(_type1(), bias_corrected=True)
    assert _u(b)["u_BI"].u == 0.0 and b.u_ms == pytest.approx(math.sqrt(4e-8 + 9e-8))


def test_the_measuring_process_by_hand():
    grr = gauge_rr(AIAG * 1e-3, tolerance=T, appraiser_is="setup")  # pooled interaction
    t1 = _type1()
    b = uncertainty_budget(t1, grr, system={"linearity": 0.0001},
                           process={"temperature": 0.0002, "object": 0.0001})  # fmt: skip
    u = _u(b)
    evo, av = grr.components["repeatability"].sd, grr.components["appraiser"].sd
    assert u["u_EVO"].u == pytest.approx(evo) and u["u_AV"].u == pytest.approx(av)
    assert u["u_IA"].u == 0.0 and u["u_IA"].origin == "pooled into repeatability"
    assert u["u_T"].u == 0.0002 and not u["u_T"].in_ms and u["u_OBJ"].in_mp
    # repeatability: the largest of u_RE, u_EVR (0.3 um) and u_EVO (0.2 um) counts
    assert u["u_EVR"].in_mp and not u["u_EVO"].in_mp and not u["u_RE"].in_mp
    u_mp = math.sqrt(4e-8 + 9e-8 + 3e-8 + 1e-8 + av**2 + 4e-8 + 1e-8)
    assert b.u_mp == pytest.approx(u_mp, rel=1e-12)
    assert b.q_mp == pytest.approx(4 * u_mp / T) and b.q_mp_ok is (4 * u_mp / T <= 0.30)
    assert b.u_ms == pytest.approx(math.sqrt(17e-8))  # the system is unchanged
    # a larger repeatability on the parts takes the place of the reference's
    noisy = gauge_rr(AIAG * 2e-3, tolerance=T)
    u2 = _u(uncertainty_budget(t1, noisy))
    assert u2["u_EVO"].in_mp and not u2["u_EVR"].in_mp and u2["u_EVR"].in_ms


def test_limits_and_verdict():
    b = uncertainty_budget(_type1(s=0.0008, bias=0.0), system={"linearity": 0.0001})
    assert b.q_ms > 0.15 and not b.q_ms_ok and b.verdict == "not capable"
    loose = uncertainty_budget(_type1(s=0.0008, bias=0.0), settings=MsaSettings(q_ms_limit=0.25))
    assert loose.q_ms_ok


@pytest.mark.parametrize(
    "kw, message",
    [({"system": {"RE": 0.001}}, "'RE': u_RE comes from the studies"),
     ({"system": {"temperature": -1.0}}, "expected a standard uncertainty >= 0"),
     ({"process": {"temperature": 0.001}}, "measuring-process sources need a gauge R&R"),
     ({"system": {"linearity": True}}, "expected a standard uncertainty")],
)  # fmt: skip
def test_bad_sources_are_refused(kw, message):
    with pytest.raises(InputError, match=message):
        uncertainty_budget(_type1(), **kw)


def test_a_source_named_twice_is_refused():
    grr = gauge_rr(AIAG * 1e-3, tolerance=T)
    with pytest.raises(InputError, match="named twice"):
        uncertainty_budget(_type1(), grr, system={"temperature": 1e-4},
                           process={"temperature": 1e-4})  # fmt: skip
