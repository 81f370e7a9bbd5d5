"""`FormationError` (formation_msgs_py.errors) is the base of every error the project raises on
purpose, and each sub-package keeps its errors in its `errors` module (issue 29)."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

from formation_msgs_py.errors import FormationError, MessageError

SRC = Path(__file__).resolve().parents[2] / 'src'
PACKAGES = ('formation_msgs_py', 'formation_agent', 'formation_sim')
# The one public error outside an errors module: it carries a ValidationReport (validate.py), and
# model.errors importing validate would close an import cycle.
OUTSIDE = {'formation_sim.model.validate': {'ValidationError'}}


def _public_exceptions() -> dict[str, dict[str, type]]:
    """module -> {name: class} of every public class under src whose base is an exception."""
    found: dict[str, dict[str, type]] = {}
    for package in PACKAGES:
        for path in sorted((SRC / package / package).rglob('*.py')):
            name = '.'.join(path.relative_to(SRC / package).with_suffix('').parts).removesuffix('.__init__')
            defined = [
                n.name
                for n in ast.parse(path.read_text(), str(path)).body
                if isinstance(n, ast.ClassDef)
                and not n.name.startswith('_')
                and any(ast.unparse(b).endswith(('Error', 'Exception')) for b in n.bases)
            ]
            if defined:
                module = importlib.import_module(name)
                found[name] = {n: getattr(module, n) for n in defined}
    return found


def test_every_public_error_is_a_formation_error_defined_in_an_errors_module():
    found = _public_exceptions()
    assert len(found) >= 9
    for module, classes in found.items():
        for name, cls in classes.items():
            assert issubclass(cls, FormationError), f'{module}.{name}'
            assert module.endswith('.errors') or name in OUTSIDE.get(module, set()), f'{module}.{name}'
    errors = {name for module, classes in found.items() if module.endswith('.errors') for name in classes}
    # The run's failures (summary.json's extra.failure.kind), in one module.
    assert {'CoordinatorError', 'AgentLostError', 'OperatorStopError', 'KeeperFrozenError'} <= errors
    # FormationError, the 52 classes moved into errors modules (issue 29) and SummaryError, at least.
    assert len(errors) >= 54 and {'FormationError', 'MessageError', 'SummaryError', 'ScenarioError'} <= errors


def test_every_error_keeps_its_built_in_base_so_older_handlers_still_catch_it():
    from formation_agent.core.errors import AgentError, CrossingError
    from formation_sim.bag.errors import BagError
    from formation_sim.model.errors import ScenarioError
    from formation_sim.model.validate import ValidationError

    assert issubclass(ScenarioError, ValueError) and issubclass(ValidationError, ValueError)
    assert issubclass(AgentError, ValueError) and issubclass(CrossingError, RuntimeError)
    assert issubclass(MessageError, ValueError) and BagError.__bases__ == (FormationError,)


def test_a_refused_input_is_caught_as_a_formation_error_naming_the_rule_and_the_value(tmp_path):
    from formation_sim.model.scenario import load_scenario

    with pytest.raises(FormationError, match='no such scenario file'):
        load_scenario(str(tmp_path / 'missing.yaml'))
    from formation_msgs_py.cdr import decode_odometry_cdr

    with pytest.raises(FormationError) as caught:
        decode_odometry_cdr(b'\x00\x01\x00\x00' + b'\x00' * 3)
    assert isinstance(caught.value, MessageError) and caught.value.reason
