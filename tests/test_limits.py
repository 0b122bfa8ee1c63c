"""Joint limits from a model and the timing of a minimum-jerk move (`cgda_jax.sim.limits`, `cgda_jax.sim.timing`)."""

import itertools
import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax import model_path
from cgda_jax.sim.limits import JointLimits, read_limits
from cgda_jax.sim.timing import (
    PEAK_ACCELERATION,
    PEAK_SPEED,
    approach_duration,
    min_duration,
    min_jerk,
    min_jerk_d1,
    min_jerk_d2,
    move_peaks,
    move_samples,
    shortest_duration,
    violation,
)

JOINTS = ["a", "b", "c", "d"]


def _model(custom: str = "", joint_extra: dict | None = None,
           actuators: str = "") -> mujoco.MjModel:
    """Four hinges a..d on a chain; ``joint_extra`` adds attributes to a joint."""
    extra = {j: "" for j in JOINTS} | dict(joint_extra or {})
    bodies = "".join(
        f'<body pos="0 0 0.1"><joint name="{j}" axis="0 1 0" {extra[j]}/>'
        f'<geom size="0.02" mass="0.1"/>' for j in JOINTS) + "</body>" * len(JOINTS)
    xml = (f"<mujoco><custom>{custom}</custom><worldbody>{bodies}</worldbody>"
           f"<actuator>{actuators}</actuator></mujoco>")
    return mujoco.MjModel.from_xml_string(xml)


def _ladder() -> mujoco.MjModel:
    """A staircase: joint a has every source, b all but a per-joint numeric, c only an
    actuator forcerange and the model-wide numeric, d only the model-wide numeric.
    Effort: per-joint numeric 7 (a); actuatorfrcrange [-8, 5] (a, b): 8; a motor's
    forcerange 2 x gear 3 (a, b, c): 6; model-wide 9 (all)."""
    custom = ('<numeric name="effort_limit" data="9"/>'
              '<numeric name="effort_limit:a" data="7"/>'
              '<numeric name="velocity_limit" data="4"/>'
              '<numeric name="velocity_limit:c" data="2.5"/>')
    extra = {"a": 'actuatorfrcrange="-8 5"', "b": 'actuatorfrcrange="-8 5"'}
    acts = "".join(f'<motor name="m_{j}" joint="{j}" forcerange="-2 2" gear="3"/>' for j in "abc")
    return _model(custom, extra, acts)


def test_each_level_wins_over_the_ones_below():
    m = _ladder()
    lim = read_limits(m, JOINTS)
    np.testing.assert_array_equal(lim.effort, [7, 8, 6, 9])
    assert lim.source["effort"] == (
        "mjcf custom effort_limit:a", "mjcf actuatorfrcrange", "mjcf forcerange:m_c",
        "mjcf custom effort_limit")
    np.testing.assert_array_equal(lim.velocity, [4, 4, 2.5, 4])
    assert lim.source["velocity"][2] == "mjcf custom velocity_limit:c"
    assert lim.source["velocity"][0] == "mjcf custom velocity_limit"
    assert np.all(np.isinf(lim.acceleration))
    assert set(lim.source["acceleration"]) == {"none"}
    assert lim.velocity.dtype == np.float32 and lim.velocity.shape == (4,)

    # overrides win over everything; a number for every joint, a table for some
    over = read_limits(m, JOINTS, {"effort": {"a": 1.5, "c": math.inf},
                                   "velocity": 3, "acceleration": {"d": 10}})
    np.testing.assert_array_equal(over.effort, [1.5, 8, np.inf, 9])
    assert over.source["effort"][:3] == ("config", "mjcf actuatorfrcrange", "config")
    np.testing.assert_array_equal(over.velocity, [3, 3, 3, 3])
    np.testing.assert_array_equal(over.acceleration, [np.inf] * 3 + [10])


def test_forcerange_times_gear_below_actuatorfrcrange_and_above_model_wide():
    acts = ('<motor joint="a" forcerange="-2 1" gear="3"/>'
            '<motor joint="a" forcerange="-1 1" gear="-2"/>'
            '<motor joint="b" forcerange="-2 2"/>'
            '<motor joint="b"/>')  # b: one actuator unlimited -> no actuator limit
    m = _model('<numeric name="effort_limit" data="9"/>', actuators=acts)
    lim = read_limits(m, ["a", "b", "c"])
    np.testing.assert_array_equal(lim.effort, [2 * 3 + 1 * 2, 9, 9])
    assert lim.source["effort"][0].startswith("mjcf forcerange:")
    assert lim.source["effort"][1:] == ("mjcf custom effort_limit",) * 2


def test_no_source_is_inf_and_the_result_reports():
    lim = read_limits(_model(), ["b", "a"])
    assert lim.joint_names == ("b", "a")
    for kind in ("velocity", "acceleration", "effort"):
        assert np.all(np.isinf(getattr(lim, kind)))
    d = lim.as_dict()
    assert d["velocity"] == {"b": None, "a": None}
    assert d["source"]["effort"] == {"b": "none", "a": "none"}
    assert "velocity=inf" in repr(lim)
    import json

    json.dumps(read_limits(_ladder(), JOINTS).as_dict())


def test_teo_reads_its_ros_limits():
    m = mujoco.MjModel.from_xml_path(str(model_path("teo.xml")))
    arm = [f"{s}_{j}" for s in "rl" for j in (
        "shoulder_flexion", "shoulder_abduction", "upper_arm_rotation", "elbow",
        "forearm_rotation", "wrist")]
    lim = read_limits(m, arm + ["trunk_axial", "trunk_frontal"])
    np.testing.assert_array_equal(lim.velocity, [3.0] * 14)
    np.testing.assert_array_equal(lim.effort[:12], [30.0] * 12)
    assert set(lim.source["effort"][:12]) == {"mjcf actuatorfrcrange"}
    assert np.all(np.isinf(lim.effort[12:]))  # the trunk: not applied (see teo.xml)
    assert np.all(np.isinf(lim.acceleration))
    for a in range(m.nu):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
        if not name.startswith("trunk"):
            assert m.actuator_forcelimited[a]
            np.testing.assert_array_equal(m.actuator_forcerange[a], [-30, 30])


@pytest.mark.parametrize("overrides, match", [
    ({"speed": 3.0}, "unknown kind 'speed'"),
    ({"velocity": {"zz": 3.0}}, "unknown joint 'zz'"),
    ({"velocity": -1.0}, r"limits.velocity = -1.0"),
    ({"velocity": 0}, r"limits.velocity = 0"),
    ({"effort": {"a": float("nan")}}, r"limits.effort.a = nan"),
    ({"effort": {"a": -math.inf}}, r"limits.effort.a = -inf"),
    ({"acceleration": "fast"}, r"limits.acceleration = 'fast'"),
    ({"acceleration": True}, r"limits.acceleration = True"),
    ({"acceleration": {"b": None}}, r"limits.acceleration.b = None"),
])
def test_bad_overrides_are_named(overrides, match):
    with pytest.raises(ValueError, match=match):
        read_limits(_model(), ["a", "b"], overrides)


@pytest.mark.parametrize("custom, match", [
    ('<numeric name="velocity_limit" data="1 2"/>', "'velocity_limit' has 2 values"),
    ('<numeric name="effort_limit:a" data="-3"/>', "'effort_limit:a' = -3"),
    ('<numeric name="acceleration_limit" size="1"/>', "'acceleration_limit' = 0"),
    ('<numeric name="velocity_limit:zz" data="3"/>', "'velocity_limit:zz': no joint"),
])
def test_bad_custom_numerics_are_named(custom, match):
    with pytest.raises(ValueError, match=match):
        read_limits(_model(custom), ["a"])


def test_unknown_joint_and_unrelated_numerics():
    with pytest.raises(KeyError, match="'nope'"):
        read_limits(_model(), ["nope"])
    m = _model('<numeric name="velocity_limits" data="1 2 3"/>'
               '<numeric name="other" data="-1"/>')
    assert np.all(np.isinf(read_limits(m, ["a"]).velocity))


def test_joint_limits_checks_its_arrays():
    with pytest.raises(ValueError, match="shape"):
        JointLimits([1.0], [1.0, 2.0], [1.0], ("a",))
    with pytest.raises(ValueError, match="> 0"):
        JointLimits([0.0], [1.0], [1.0], ("a",))
    lim = JointLimits([1.0], [np.inf], [2.0], ("a",))
    assert lim.source["velocity"] == ("none",)
    with pytest.raises(ValueError):
        lim.velocity[0] = 5.0  # read-only


# -- the minimum-jerk move ---------------------------------------------------------
def _fine(n=200_001):
    return np.linspace(0.0, 1.0, n)


def test_profile_and_its_derivatives_match_finite_differences():
    tau = _fine()
    s = np.asarray(min_jerk(tau), np.float64)
    assert s[0] == 0 and abs(s[-1] - 1) < 1e-6
    # reference polynomials in float64 (float32 positions are too coarse to difference)
    s64 = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    np.testing.assert_allclose(s, s64, atol=1e-6)
    d1 = np.gradient(s64, tau)
    d2 = np.gradient(d1, tau)
    np.testing.assert_allclose(np.asarray(min_jerk_d1(tau)), d1, atol=1e-4)
    np.testing.assert_allclose(np.asarray(min_jerk_d2(tau))[2:-2], d2[2:-2], atol=1e-3)
    # clipped: held before and after
    np.testing.assert_array_equal(np.asarray(min_jerk(jnp.array([-1.0, 2.0]))), [0, 1])
    np.testing.assert_array_equal(np.asarray(min_jerk_d1(jnp.array([-1.0, 2.0]))), 0)
    np.testing.assert_array_equal(np.asarray(min_jerk_d2(jnp.array([-1.0, 2.0]))), 0)


def test_the_host_profile_is_the_traced_one():
    """`cgda_jax.numerics.min_jerk_np` (NumPy, float64) and `min_jerk` (JAX,
    float32): one profile, clipped alike outside [0, 1]."""
    from cgda_jax.numerics import min_jerk_np

    tau = np.linspace(-0.5, 1.5, 20_001)
    s64 = np.clip(tau, 0, 1) ** 3 * (10 - 15 * np.clip(tau, 0, 1)
                                     + 6 * np.clip(tau, 0, 1) ** 2)
    np.testing.assert_allclose(min_jerk_np(tau), s64, rtol=0, atol=1e-15)
    np.testing.assert_allclose(min_jerk_np(tau), np.asarray(min_jerk(tau)), atol=1e-6)
    assert min_jerk_np(tau).dtype == np.float64


def test_move_peaks_are_the_closed_form_and_the_sampled_maxima():
    dq = np.array([0.7, -1.3, 0.0, 2.0])
    T = 0.8
    speed, acc = (np.asarray(x) for x in move_peaks(jnp.asarray(dq), T))
    np.testing.assert_allclose(speed, 1.875 * np.abs(dq) / T, rtol=1e-6)
    np.testing.assert_allclose(acc, 10 / math.sqrt(3) * np.abs(dq) / T**2, rtol=1e-6)
    assert PEAK_SPEED == 1.875 and abs(PEAK_ACCELERATION - 5.7735) < 1e-4
    # finite differences of float64 positions on a fine grid of time
    t = _fine() * T
    tau = t / T
    q = np.outer(10 * tau**3 - 15 * tau**4 + 6 * tau**5, dq)
    v = np.gradient(q, t, axis=0)
    a = np.gradient(v, t, axis=0)
    np.testing.assert_allclose(np.abs(v).max(0), speed, rtol=1e-4)
    np.testing.assert_allclose(np.abs(a[2:-2]).max(0), acc, rtol=1e-4)


def test_move_samples_match_finite_differences():
    q0 = np.array([0.1, -0.5, 0.3])
    q1 = np.array([1.2, -0.1, 0.3])
    T, n = 1.5, 30_001
    fn = jax.jit(move_samples, static_argnames="n")
    out = fn(jnp.asarray(q0), jnp.asarray(q1), T, n=n)
    t, q, qd, qdd = (np.asarray(x, np.float64) for x in out)
    assert t.shape == (n,) and q.shape == qd.shape == qdd.shape == (n, 3)
    np.testing.assert_allclose(t[[0, -1]], [0, T], atol=1e-6)
    np.testing.assert_allclose(q[0], q0, atol=1e-6)
    np.testing.assert_allclose(q[-1], q1, atol=1e-6)
    tau = np.linspace(0, 1, n)
    q64 = q0 + np.outer(10 * tau**3 - 15 * tau**4 + 6 * tau**5, q1 - q0)
    np.testing.assert_allclose(q, q64, atol=1e-5)
    v = np.gradient(q64, tau * T, axis=0)
    a = np.gradient(v, tau * T, axis=0)
    np.testing.assert_allclose(qd, v, atol=1e-4 * np.abs(v).max())
    np.testing.assert_allclose(qdd[2:-2], a[2:-2], atol=1e-3 * np.abs(a).max())
    speed, acc = move_peaks(jnp.asarray(q1 - q0), T)
    np.testing.assert_allclose(np.abs(qd).max(0), speed, rtol=1e-4)
    np.testing.assert_allclose(np.abs(qdd).max(0), acc, rtol=1e-4)
    with pytest.raises(ValueError, match="n >= 2"):
        move_samples(q0, q1, T, 1)


def _limits(v, a, e=None):
    n = len(v)
    return JointLimits(v, a, [np.inf] * n if e is None else e,
                       tuple(f"j{i}" for i in range(n)))


def test_min_duration_makes_the_binding_limit_exact():
    lim = _limits([2.0, 1.0, np.inf], [10.0, np.inf, 3.0])
    for dq in ([1.0, 0.2, 0.1], [0.1, 0.1, 2.0], [0.0, 0.5, 0.0], [0.3, -0.4, 1.0]):
        dq = jnp.asarray(dq)
        T = float(min_duration(dq, lim))
        speed, acc = (np.asarray(x) for x in move_peaks(dq, T))
        ratio = np.concatenate([speed / lim.velocity, acc / lim.acceleration])
        assert np.all(ratio <= 1 + 1e-5)
        assert abs(ratio.max() - 1) < 1e-5  # one limit is reached exactly
        assert float(violation(speed, acc, lim)) < 1e-5
    assert float(min_duration(jnp.zeros(3), lim)) == 0.0
    # unlimited joints that move need no time; jit, vmap and grad work (limits: pytree)
    free = _limits([np.inf] * 2, [np.inf] * 2)
    assert float(min_duration(jnp.ones(2), free)) == 0.0
    batch = jax.jit(jax.vmap(min_duration, (0, None)))(jnp.ones((5, 3)), lim)
    assert batch.shape == (5,)
    g = jax.grad(lambda d: min_duration(d, lim))(jnp.zeros(3))
    assert np.all(np.isfinite(np.asarray(g)))


def test_shortest_duration_with_jerk_against_a_sampled_profile():
    """NumPy float64 path with a jerk limit (the export's minimum-jerk mover): the
    move of that duration, sampled densely and differentiated numerically (not the
    closed-form peaks), keeps every limit and reaches one of them; 1 % faster
    breaks one."""
    v, a, j = np.array([2.0, 1.0, np.inf]), np.array([10.0, np.inf, 3.0]), \
        np.array([40.0, 5.0, np.inf])
    n = 20001

    def peaks(dq, T):
        t = np.linspace(0.0, T, n)
        tau = t / T
        q = np.outer(10 * tau**3 - 15 * tau**4 + 6 * tau**5, dq)
        d = [q]
        for _ in range(3):
            d.append(np.gradient(d[-1], t, axis=0))
        return [np.abs(x[5:-5]).max(axis=0) for x in d[1:]]  # speed, acc, jerk

    for dq in ([1.0, 0.2, 0.1], [0.1, 0.1, 2.0], [0.0, 0.5, 0.0], [0.3, -0.4, 1.0]):
        dq = np.asarray(dq)
        T = float(shortest_duration(np.abs(dq), v, a, j))
        ratios = np.concatenate([p / lim for p, lim in zip(peaks(dq, T), (v, a, j))])
        assert np.all(ratios <= 1 + 2e-3) and ratios.max() > 1 - 2e-3, ratios
        faster = np.concatenate([p / lim for p, lim in
                                 zip(peaks(dq, 0.99 * T), (v, a, j))])
        assert faster.max() > 1.005
    assert float(shortest_duration(np.zeros(3), v, a, j)) == 0.0
    # without the jerk limit: min_duration's value (float32 JAX path)
    lim = _limits(v, a)
    dq = np.array([0.3, -0.4, 1.0])
    np.testing.assert_allclose(shortest_duration(np.abs(dq), v, a),
                               float(min_duration(jnp.asarray(dq), lim)), rtol=1e-6)


def test_approach_duration_is_the_worst_corner_of_the_box():
    rng = np.random.default_rng(3)
    lim = _limits([2.0, 1.0, 3.0], [10.0, 4.0, np.inf])
    for _ in range(5):
        lower = rng.uniform(-2, -0.1, 3)
        upper = rng.uniform(0.1, 2, 3)
        start = rng.uniform(lower, upper)
        got = approach_duration(lower, upper, start, lim, floor=0.0)
        assert isinstance(got, float)
        corners = np.array(list(itertools.product(*zip(lower, upper))))
        brute = max(float(min_duration(jnp.asarray(c - start), lim)) for c in corners)
        grid = np.stack(np.meshgrid(*[np.linspace(lo, hi, 7) for lo, hi
                                      in zip(lower, upper)]), -1).reshape(-1, 3)
        inside = float(jnp.max(jax.vmap(min_duration, (0, None))(
            jnp.asarray(grid - start), lim)))
        assert abs(got - brute) < 1e-5 * brute
        assert inside <= got * (1 + 1e-5)
    assert approach_duration(lower, upper, start, lim, floor=100.0) == 100.0
    assert approach_duration(start, start, start, lim) == 0.0
    with pytest.raises(ValueError, match="floor"):
        approach_duration(lower, upper, start, lim, floor=-1)
    with pytest.raises(ValueError, match="unbounded"):
        approach_duration([-np.inf, 0, 0], upper, [0, 0, 0], lim)


def test_violation_zero_inside_positive_outside_ignores_inf():
    lim = _limits([2.0, np.inf], [10.0, 4.0], [5.0, np.inf])
    assert float(violation(jnp.array([1.0, 1e6]), jnp.array([10.0, 4.0]), lim)) == 0.0
    assert float(violation(jnp.array([3.0, 0.0]), jnp.array([0.0, 0.0]), lim)) == \
        pytest.approx(0.5)
    assert float(violation(jnp.array([0.0, 0.0]), jnp.array([0.0, 6.0]), lim)) == \
        pytest.approx(0.5)
    # effort only when given
    assert float(violation(jnp.zeros(2), jnp.zeros(2), lim, jnp.array([10.0, 1e9]))) \
        == pytest.approx(1.0)
    v = jax.jit(violation)(jnp.array([3.0, 1.0]), jnp.array([20.0, 1.0]), lim)
    assert float(v) == pytest.approx(1.0) and np.isfinite(float(v))
    batched = jax.vmap(violation, (0, 0, None))(jnp.ones((4, 2)), jnp.ones((4, 2)), lim)
    assert batched.shape == (4,)
    g = jax.grad(lambda s: violation(s, jnp.zeros(2), lim))(jnp.array([3.0, 1.0]))
    np.testing.assert_allclose(np.asarray(g), [0.5, 0.0])
