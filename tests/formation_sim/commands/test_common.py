"""formation_sim.commands.common: a scenario's warnings, and the one line that says why the paper's
own examples raise theirs (what `make demo` opens with)."""

from __future__ import annotations

import pytest
import yaml

from formation_sim.commands.common import load_valid_scenario


def _warnings(capsys) -> list[str]:
    return capsys.readouterr().err.splitlines()


def test_the_paper_examples_warnings_are_said_to_be_expected_and_why(capsys):
    assert load_valid_scenario('paper_single', 'run') is not None
    lines = _warnings(capsys)
    assert [line.split(':')[0] for line in lines] == ['warning', 'warning', 'note']
    assert '4.6 %' in lines[0] and 'Remark 3.2' in lines[1]  # formation validate's own words, unchanged
    assert lines[2].startswith("note: these warnings are expected for the paper's example (Section 5)")
    assert (
        'edge (2, 3) starts that close to Δ' in lines[2]
        and "the Remark's bound only limits what an agent can check locally" in lines[2]
    )
    assert load_valid_scenario('paper_double', 'run') is not None
    assert 'corrected rate condition of Theorem 2' in _warnings(capsys)[-1]


def test_other_scenarios_keep_their_warnings_without_the_note(
    capsys, tmp_path, tight_edge, paper_scenario_dict
):
    from formation_sim.model.scenario import dump_scenario

    copy = tmp_path / 'paper_copy.yaml'
    copy.write_text(
        yaml.safe_dump(paper_scenario_dict())
    )  # the paper's values, but not the paper's example by name
    assert load_valid_scenario(str(copy), 'run') is not None
    lines = _warnings(capsys)
    assert len(lines) == 2 and all(line.startswith('warning: ') for line in lines)
    assert load_valid_scenario('robots_square', 'run') is not None
    assert _warnings(capsys) == []
    tight = tmp_path / 'tight.yaml'
    dump_scenario(tight_edge('paper_single', 0.01), tight)
    assert load_valid_scenario(str(tight), 'run') is not None
    assert not any(line.startswith('note:') for line in _warnings(capsys))


def _robots(model: str, **shape):
    from formation_sim.runtime.launch.plan import RobotOptions

    return RobotOptions.of(model=model, **shape)


def test_robot_backends_keep_the_origins_apart_by_default_with_the_kinds_footprints(capsys):
    """Issue 27: no --min-separation and no safety: key on a robot backend turns the layer on with
    D = 2r + 5 cm between origins, D + 2l between a unicycle's control points (l = 0.1 m)."""
    from formation_sim.commands.common import robot_safety
    from formation_sim.model.scenario import load_scenario

    scenario = load_scenario('robots_square')
    safe, extra = robot_safety(scenario, None, _robots('unicycle'))
    assert (
        extra['origin_separation'] == 2 * 0.105 + 0.05
        and extra['source'] == 'unicycle footprints (r = 0.105 m)'
    )
    assert (
        safe.safety.min_separation
        == extra['control_point_separation']
        == pytest.approx(0.26 + 2 * 0.1, rel=1e-15)
    )
    assert (
        "keeps the robots' origins 0.26 m apart (unicycle footprints (r = 0.105 m))"
        in capsys.readouterr().err
    )
    safe, extra = robot_safety(scenario, None, _robots('holonomic'))  # its control point is its origin
    assert safe.safety.min_separation == extra['origin_separation'] == 2 * 0.07 + 0.05
    safe, extra = robot_safety(scenario, None, _robots('unicycle', footprint_radius=0.22))  # a Waffle
    assert safe.safety.min_separation == pytest.approx(0.44 + 0.05 + 0.2, rel=1e-15)


def test_a_given_separation_is_between_origins_and_zero_turns_the_layer_off(capsys):
    from formation_agent.core.safety import SafetyConfig
    from formation_sim.commands.common import robot_safety
    from formation_sim.model.scenario import load_scenario

    scenario = load_scenario('robots_square')
    safe, extra = robot_safety(scenario, 0.25, _robots('unicycle'))
    assert (
        safe.safety.min_separation == pytest.approx(0.25 + 0.2, rel=1e-15)
        and extra['source'] == '--min-separation'
    )
    keyed = scenario.replace(safety=SafetyConfig(min_separation=0.3, gamma=3.0))
    safe, extra = robot_safety(keyed, None, _robots('unicycle'))  # the scenario's D: origins too
    assert (safe.safety.min_separation, safe.safety.gamma) == (pytest.approx(0.3 + 0.2, rel=1e-15), 3.0)
    assert extra['source'] == 'scenario safety.min_separation'
    off, extra = robot_safety(keyed, 0.0, _robots('unicycle'))
    assert off.safety is None and extra == {'layer': 'off', 'source': '--min-separation 0'}
    assert 'the safety layer is off (--min-separation 0)' in capsys.readouterr().err


def test_the_default_stays_off_where_it_cannot_apply_and_says_why(capsys):
    """ETA-2 (the layer is ETA-1's): off, said. F1TENTH cars (D_s = 1.69 m) on the 1 m square: the
    formation has no room for their footprints, so the default keeps 0.9 of its closest pair between
    control points and says so; cars whose control points reach too far for that: off with a warning
    naming the rule. Asked for explicitly, a separation the layer cannot take is refused."""
    from formation_sim.commands.common import robot_safety
    from formation_sim.model.scenario import load_scenario

    double, extra = robot_safety(load_scenario('robots_lab_double'), None, _robots('holonomic'))
    assert double.safety is None and extra == {'layer': 'off', 'source': 'double, dimension 2'}
    cars = _robots('car', control_point_distance=0.33, wheelbase=0.33)
    square = load_scenario('robots_square')
    fitted, extra = robot_safety(square, None, cars)  # D_s = 1.69 m does not fit the 1 m square
    assert fitted.safety.min_separation == pytest.approx(0.9)  # 0.9 of the formation's 1 m
    assert extra['origin_separation'] == pytest.approx(0.9 - 0.66) and 'fitted' in extra['source']
    err = capsys.readouterr().err
    assert (
        "the formation itself puts agents 1 and 2 1 m apart, not more than the control points' separation "
        '1.69 m: the layer keeps them 0.9 m apart instead (0.9 of it), their origins 0.24 m: less than the '
        "robots' footprints" in err
    )
    long_cars = _robots('car', control_point_distance=0.5, wheelbase=0.33)  # 0.9 m leaves no room: off
    off, extra = robot_safety(square, None, long_cars)
    assert off.safety is None and extra['layer'] == 'off'
    assert 'warning: the safety layer is off' in capsys.readouterr().err
    assert (
        robot_safety(square, 1.6, _robots('unicycle')) is None
    )  # D_s = 1.8 m: ρ* = (1 + sqrt(1 + 1.8²·4)) / 2
    err = capsys.readouterr().err
    assert 'must exceed the guard radius ρ* = (2 v̄ + sqrt(4 v̄² + γ² D²)) / γ = 2.36815 m' in err
    assert "the robots' origins 1.6 m apart, from --min-separation, are their control points 1.8 m" in err


def test_a_start_inside_the_margin_runs_and_only_overlapping_robots_are_refused(capsys):
    """Issue 27 leftover 1: control points closer than D_s start in recovery (docs/SAFETY.md (S9)),
    said on stderr; robots whose origins are no more than two footprints apart are refused, with
    the pair, the distance and the rule."""
    from formation_sim.commands.common import robot_safety
    from formation_sim.model.scenario import load_scenario

    square = load_scenario('robots_square')
    safe, extra = robot_safety(square, 0.9, _robots('unicycle'))  # 1.1 m between control points
    assert (
        safe.safety.min_separation == pytest.approx(1.1)
        and extra['control_point_separation'] == safe.safety.min_separation
    )
    err = capsys.readouterr().err
    assert (
        'start 0.992613 m apart, inside the separation 1.1 m: the safety layer moves every such pair' in err
    )
    near = square.positions.copy()
    near[1] = near[0] + [
        0.15,
        0.2,
    ]  # 0.25 m: more than 2r = 0.21 m for Burgers, less than 0.28 m for r = 0.14
    close = square.replace(positions=near)
    assert robot_safety(close, None, _robots('unicycle'))[0].safety is not None
    capsys.readouterr()
    assert robot_safety(close, None, _robots('unicycle', footprint_radius=0.14)) is None
    err = capsys.readouterr().err
    assert (
        'formation run: error: robots overlap: agents 1 and 2 are set down with their origins 0.25 m apart, '
        'not more than two footprints 2r = 0.28 m (unicycle, r = 0.14 m' in err
    )


def test_cars_take_the_default_on_a_formation_that_has_room_for_them(capsys):
    """Issue 27 leftover 2: F1TENTH cars (r = 0.49 m, l = 0.33 m: D = 1.03 m, D_s = 1.69 m) on the
    square scaled 3× (3 m sides): the default applies, its guard radius ρ* = (1 + sqrt(1 + 4 · 1.69²))
    / 2 = 2.26241 m beyond the default R = 2 m, so R = ρ* + 2 v̄ · 1 s = 3.26241 m."""
    from formation_sim.commands.common import robot_safety
    from formation_sim.model.scenario import Edge, load_scenario

    square = load_scenario('robots_square')
    big = square.replace(
        positions=3.0 * square.positions,
        edges=tuple(Edge(i=e.i, j=e.j, d=3.0 * e.d) for e in square.edges),
        delta=3.0 * square.delta,
    )
    cars = _robots('car', control_point_distance=0.33, wheelbase=0.33)
    safe, extra = robot_safety(big, None, cars)
    assert safe.safety.min_separation == pytest.approx(1.69)
    assert safe.safety.sensing_radius == pytest.approx(3.26241, abs=1e-5)
    assert extra['origin_separation'] == pytest.approx(1.03)
    err = capsys.readouterr().err
    assert 'the default sensing radius 2 m is within the guard radius ρ* = 2.262 m' in err
    assert "keeps the robots' origins 1.03 m apart (car footprints (r = 0.49 m))" in err
