"""The architecture, as a rule the imports must keep (docs/DESIGN.md, "Layers").

- Packages depend one way: formation_sim -> formation_agent -> formation_msgs_py.
- formation_sim's layers: model < sim < bag < analysis < study < runtime < commands < cli; a module
  imports only from its own layer or those before it (function-level imports included).
- formation_agent.core never imports formation_agent.ros.
- formation_sim.runtime by role: nothing under runtime.launch (the parent) imports runtime.nodes
  (the node programs) or the other way round; both agree through runtime.contract, which imports
  neither, and the tools (runtime.tools) may use both.
- No import cycle among the project's modules.
- Everything but the ROS shells imports with rclpy and the ROS message packages unavailable.
- Every name a package face exports (`__all__`) resolves.
"""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / 'src'
PACKAGES = ('formation_msgs_py', 'formation_agent', 'formation_sim')
SIM_LAYERS = ('progress', 'model', 'sim', 'bag', 'analysis', 'study', 'runtime', 'commands', 'cli')
# Modules that are ROS shells: they may import rclpy at the top.
ROS_MODULES = ('formation_msgs_py.qos', 'formation_agent.ros', 'formation_sim.runtime')
ROS_IMPORTS = (
    'rclpy',
    'std_msgs',
    'std_srvs',
    'geometry_msgs',
    'rosgraph_msgs',
    'visualization_msgs',
    'builtin_interfaces',
    'nav_msgs',
    'sensor_msgs',
    'rcl_interfaces',
)


def _modules() -> dict[str, Path]:
    found = {}
    for package in PACKAGES:
        root = SRC / package / package
        for path in root.rglob('*.py'):
            parts = path.relative_to(root.parent).with_suffix('').parts
            name = '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)
            found[name] = path
    return found


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """Project modules `name` imports anywhere in its body (a package's submodule when named)."""
    targets = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            candidates = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            candidates = [f'{node.module}.{alias.name}' for alias in node.names] + [node.module]
        else:
            continue
        for candidate in candidates:
            if candidate in MODULES:
                targets.add(candidate)
                break  # `from pkg import submodule` names the submodule, else the module itself
    targets.discard(name)
    return targets


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _package_rank(name: str) -> int:
    return PACKAGES.index(name.split('.', maxsplit=1)[0])


def _sim_layer(name: str) -> int:
    parts = name.split('.')
    return SIM_LAYERS.index(parts[1]) if len(parts) > 1 else len(SIM_LAYERS)  # the face: above all


def test_the_module_list_is_complete() -> None:
    assert {
        'formation_agent.core.eta',
        'formation_sim.model.scenario',
        'formation_sim.runtime.nodes.sim_node',
    } <= set(MODULES)
    assert all(GRAPH[name] for name in ('formation_sim.sim.engine', 'formation_agent.ros.node'))


def test_packages_depend_one_way() -> None:
    upward = [(a, b) for a, targets in GRAPH.items() for b in targets if _package_rank(b) > _package_rank(a)]
    assert not upward, upward


def test_formation_sim_layers_import_only_downward() -> None:
    upward = [
        f'{a} ({SIM_LAYERS[_sim_layer(a)] if _sim_layer(a) < len(SIM_LAYERS) else "face"}) -> {b}'
        for a, targets in GRAPH.items()
        if a.startswith('formation_sim.')
        for b in targets
        if b.startswith('formation_sim.') and _sim_layer(b) > _sim_layer(a)
    ]
    assert not upward, upward


def test_the_agent_core_never_imports_its_ros_shell() -> None:
    wrong = [
        (a, b)
        for a, targets in GRAPH.items()
        if a.startswith('formation_agent.core')
        for b in targets
        if b.startswith('formation_agent.ros')
    ]
    assert not wrong, wrong


def test_no_import_cycle() -> None:
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(name: str) -> list[str] | None:
        state[name] = 1
        stack.append(name)
        for target in sorted(GRAPH[name]):
            if state.get(target) == 1:
                return stack[stack.index(target) :] + [target]
            if target not in state and (cycle := visit(target)):
                return cycle
        stack.pop()
        state[name] = 2
        return None

    for name in sorted(GRAPH):
        if name not in state:
            assert (cycle := visit(name)) is None, ' -> '.join(cycle)


def test_the_rule_catches_an_upward_import(tmp_path) -> None:
    # The checks above must be able to fail: an analysis module importing the runtime is found.
    probe = tmp_path / 'probe.py'
    probe.write_text('def f():\n    from formation_sim.runtime.launch.orchestrate import FormationRun\n')
    targets = _imports('formation_sim.analysis.probe', probe)
    assert targets == {'formation_sim.runtime.launch.orchestrate'}
    assert _sim_layer('formation_sim.runtime.launch.orchestrate') > _sim_layer('formation_sim.analysis.probe')


ROLES = ('nodes', 'launch', 'tools')
# role -> the roles it must not import: the parent starts node programs by their module names and
# agrees with them through runtime.contract; the node programs know nothing of who started them.
ROLE_BARRIERS = {'launch': ('nodes', 'tools'), 'nodes': ('launch', 'tools'), '': ROLES}


def _role(name: str) -> str | None:
    """'nodes', 'launch' or 'tools' for a module of that folder of formation_sim.runtime, '' for
    one beside them (contract, errors, testing), None outside the runtime."""
    parts = name.split('.')
    if parts[:2] != ['formation_sim', 'runtime'] or len(parts) < 3:
        return None
    return parts[2] if parts[2] in ROLES else ''


def _role_breaches(graph: dict[str, set[str]]) -> list[str]:
    return [
        f'{a} ({_role(a) or "runtime"}) -> {b} ({_role(b)})'
        for a, targets in graph.items()
        if _role(a) is not None and a != 'formation_sim.runtime.testing'  # a test helper: replays bags
        for b in targets
        if _role(b) in ROLE_BARRIERS.get(_role(a) or '', ())
    ]


def test_each_runtime_role_folder_holds_only_its_role() -> None:
    assert {'formation_sim.runtime.launch.plan', 'formation_sim.runtime.nodes.sim_node'} <= set(MODULES)
    assert all(_role(name) is not None for name in MODULES if name.startswith('formation_sim.runtime.'))
    breaches = _role_breaches(GRAPH)
    assert not breaches, 'import what both sides need from formation_sim.runtime.contract:\n' + '\n'.join(
        breaches
    )


def test_the_role_rule_catches_the_launch_side_importing_a_node(tmp_path) -> None:
    # As launch.py did before the split: a node module imported inside a function is found.
    probe = tmp_path / 'probe.py'
    probe.write_text('def f():\n    from formation_sim.runtime.nodes.sim_node import SIMULATOR_PARAMETERS\n')
    graph = {'formation_sim.runtime.launch.probe': _imports('formation_sim.runtime.launch.probe', probe)}
    assert _role_breaches(graph) == [
        'formation_sim.runtime.launch.probe (launch) -> formation_sim.runtime.nodes.sim_node (nodes)'
    ]
    graph = {'formation_sim.runtime.contract': {'formation_sim.runtime.launch.plan'}}
    assert _role_breaches(graph) == [
        'formation_sim.runtime.contract (runtime) -> formation_sim.runtime.launch.plan (launch)'
    ]


ROS_FREE = sorted(name for name in MODULES if not name.startswith(ROS_MODULES))

_BLOCKER = f"""
import importlib.abc, sys
BLOCKED = {ROS_IMPORTS!r}
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in BLOCKED:
            raise ModuleNotFoundError(f'{{name}} is blocked: this module must not need ROS', name=name)
        return None
sys.meta_path.insert(0, Block())
import importlib
for name in sys.argv[1:]:
    importlib.import_module(name)
    assert not [m for m in sys.modules if m.split('.')[0] in BLOCKED], name
print('imported', len(sys.argv) - 1)
"""


def test_ros_free_modules_import_without_rclpy() -> None:
    assert len(ROS_FREE) > 40 and 'formation_sim.analysis.figures' in ROS_FREE
    run = subprocess.run(
        [sys.executable, '-c', _BLOCKER, *ROS_FREE], capture_output=True, text=True, timeout=300, check=False
    )
    assert run.returncode == 0, run.stderr[-3000:]
    assert run.stdout.strip() == f'imported {len(ROS_FREE)}'


# Modules of the ROS layers that hold no node and must import without ROS all the same: the run's
# books are tested, and read by tools, on machines without ROS; the orchestrators start and watch
# node processes and load no ROS themselves (an rclpy process costs ~65 MB and 0.3-0.6 s).
ROS_FREE_IN_ROS_LAYERS = (
    'formation_sim.runtime.nodes.run_book',
    'formation_agent.ros.process',
    'formation_sim.runtime.launch.orchestrate',
    'formation_sim.runtime.launch.fleet',
    'formation_sim.runtime.contract',
)


@pytest.mark.parametrize('name', ROS_FREE_IN_ROS_LAYERS)
def test_books_of_the_ros_layers_import_without_rclpy(name: str) -> None:
    assert name.startswith(ROS_MODULES) and name in MODULES
    run = subprocess.run(
        [sys.executable, '-c', _BLOCKER, name], capture_output=True, text=True, timeout=120, check=False
    )
    assert run.returncode == 0, run.stderr[-3000:]


def test_the_blocker_blocks() -> None:
    run = subprocess.run(
        [sys.executable, '-c', _BLOCKER, 'formation_agent.ros.node'],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert run.returncode != 0 and 'rclpy is blocked' in run.stderr


@pytest.mark.parametrize(
    'package', sorted(name for name, path in MODULES.items() if path.name == '__init__.py')
)
def test_every_exported_name_resolves(package: str) -> None:
    module = importlib.import_module(package)
    for name in getattr(module, '__all__', ()):
        assert getattr(module, name) is not None, f'{package}.{name}'
