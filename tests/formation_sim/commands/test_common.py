"""formation_sim.commands.common: a scenario's warnings, and the one line that says why the paper's
own examples raise theirs (what `make demo` opens with)."""

from __future__ import annotations

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
