"""A failed wheel (`spacecraft.failed_wheels`): its drive gives no torque.

- checked at load (a known wheel, named once);
- the plant holds the failed wheel's acceleration at 0 whatever it is commanded (it coasts: its speed stays, its
  momentum stays in Euler's equations), with the filter and without it;
- the filter leaves the wheel out of u (its answer is 0 there) and, with three wheels, holds what the two left
  can: on the paper's example its most important level (the rates, the wheel speeds, the exclusion zone) holds at
  every substep while the battery gives way, as `filter.priorities` orders them;
- filter_status says it: the `wheels` key and an ERROR entry, one line.
"""

from __future__ import annotations

import numpy as np
import pytest

from rta_attitude import config
from rta_attitude.config.schema import group_of
from rta_attitude.dynamics.state import PSI
from rta_attitude.errors import ConfigError
from rta_attitude.filter.asif import AsifFilter
from rta_attitude.montecarlo.sampling import sample_initial_states
from rta_attitude.simulation.closed_loop import simulate

FAILED = {"spacecraft.failed_wheels": "wheel_x"}


def test_a_failed_wheel_is_checked_at_load() -> None:
    with pytest.raises(ConfigError, match="unknown wheel 'wheel_w'"):
        config.load(overrides={"spacecraft.failed_wheels": "wheel_w"})
    with pytest.raises(ConfigError, match="names a wheel twice"):
        config.load(overrides={"spacecraft.failed_wheels": "wheel_y, wheel_y"})
    cfg = config.load(overrides=FAILED)
    assert cfg.spacecraft.control_lost == "lost 3-axis control: wheel_x failed, 2 wheels left"
    assert cfg.u_max_rad_s2[0] == 0.0
    np.testing.assert_array_equal(cfg.u_max_rad_s2[1:], config.load().u_max_rad_s2[1:])
    assert config.load().spacecraft.control_lost == ""


@pytest.mark.parametrize("rta", [True, False], ids=["rta", "no-rta"])
def test_the_plant_holds_a_failed_wheel_at_zero(rta: bool) -> None:
    """The PD commands every wheel; the failed one's applied acceleration is 0 at every step and its speed stays
    where it was, while the others move."""
    cfg = config.load(overrides=FAILED)
    tr = simulate(cfg, "paper-example", rta=rta, duration_s=300.0)
    u = np.asarray(tr.u)
    assert np.all(u[:, 0] == 0.0)
    assert np.all(tr.x[:, PSI.start] == tr.x[0, PSI.start])
    assert np.abs(u[:, 1:]).max() > 1.0
    assert np.abs(np.asarray(tr.u_des)[:, 0]).max() > 1.0  # the controller did ask for it


def test_the_filter_leaves_a_failed_wheel_out_and_holds_what_it_can() -> None:
    """The filter's own answer is 0 on the failed wheel for desired commands that ask for it, at Monte Carlo
    states; on the paper's example (communication slacked) the first level of `filter.priorities` (the rates, the
    wheel speeds, the exclusion zone) holds at every substep with two wheels, and what gives way is below it."""
    cfg = config.load(overrides=FAILED)
    f = AsifFilter(cfg.with_backup("none"))
    x, _ = sample_initial_states(40, 5, cfg)
    rng = np.random.default_rng(5)
    for k in range(len(x)):
        r = f.filter(x[k], rng.uniform(-30.0, 30.0, 3))
        assert r.u[0] == 0.0, (k, r.u)
    tr = simulate(cfg, "paper-example")
    first = set(cfg.priority_levels[0])
    assert {"omega", "psi", "exclusion_zone"} <= first
    worst = dict(zip(tr.names, tr.h_substep_min.min(axis=0)))
    for name in tr.names:
        if group_of(name) in first:
            assert worst[name] >= 0.0, (name, worst[name])
    assert min(worst[n] for n in tr.names) < 0.0  # with two wheels not everything holds: something gave way


def test_filter_status_says_3_axis_control_is_lost() -> None:
    """The `wheels` key of the filter entry names what is lost, and the entry is an ERROR; 'ok' otherwise."""
    from diagnostic_msgs.msg import DiagnosticStatus

    from rta_attitude import topics
    from rta_attitude.filter.asif import FilterCounters
    from rta_attitude.ros import convert

    cfg = config.load(overrides=FAILED)
    f = AsifFilter(cfg.with_backup("none"))
    x = cfg.scenario("paper-example").x0
    res = f.filter(x, np.array([10.0, 0.0, 0.0]))
    for wheels, level in ((cfg.spacecraft.control_lost, DiagnosticStatus.ERROR), ("", None)):
        msg = convert.FilterStatusBuilder(res.names, wheels).build(res, 0, FilterCounters(), "robust", ())
        entry = msg.status[0]
        values = {kv.key: kv.value for kv in entry.values}
        assert values["wheels"] == (wheels or "ok")
        assert list(values) == list(topics.QP_KEYS)
        if level is not None:
            assert entry.level == level and entry.message.startswith("lost 3-axis control: wheel_x failed")
        else:
            assert not entry.message.startswith("lost")


def test_a_wheel_fails_while_the_nodes_run() -> None:
    """`ros2 param set` of spacecraft.failed_wheels on the plant node (the fault injection) and on the filter node
    (what the filter is told): the plant's actuator holds the wheel at 0 from then on, the filter's next answer
    leaves it out and its filter_status says 3-axis control is lost; set back to '', both work again. A name that
    is not a wheel is refused with the loader's line."""
    import rclpy
    from rclpy.parameter import Parameter
    from test_nodes import NODE_CLASSES, NS

    from rta_attitude import topics
    from rta_attitude.dynamics import spacecraft

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        plant = NODE_CLASSES[topics.PLANT](context=context, namespace=NS)
        filt = NODE_CLASSES[topics.FILTER](context=context, namespace=NS)
        x = plant.cfg.scenario("paper-example").x0
        u = np.array([20.0, -10.0, 5.0])
        assert spacecraft.saturated(u, plant.simulator.record)[0] == 20.0
        bad = plant.set_parameters([Parameter("spacecraft.failed_wheels", value="wheel_q")])[0]
        ok = [n.set_parameters([Parameter("spacecraft.failed_wheels", value="wheel_x")])[0] for n in (plant, filt)]
        held = spacecraft.saturated(u, plant.simulator.record)
        answer = filt.filter.filter(x, u)
        status = filt.status_builder.build(answer, 0, filt.filter.counters, "robust", ()).status[0]
        back = [n.set_parameters([Parameter("spacecraft.failed_wheels", value="")])[0] for n in (plant, filt)]
        again = filt.filter.filter(x, u)
        for node in (plant, filt):
            node.close()
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    assert not bad.successful and "unknown wheel 'wheel_q'" in bad.reason
    assert all(r.successful for r in ok + back)
    assert held[0] == 0.0 and held[1] == -10.0
    assert answer.u[0] == 0.0
    assert status.message.startswith("lost 3-axis control: wheel_x failed")
    assert again.u[0] != 0.0
