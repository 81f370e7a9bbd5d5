"""Example parameter files for robots (README, "Running on robots"), one per robot kind
(`RobotKind.params_file`, `formation_agent.core.kinds`): `turtlebot3.params.yaml` (unicycle,
differential drive), `crazyflie.params.yaml` (holonomic, ETA-2) and `car.params.yaml` (car).

They ship inside the package, so every install has them beside this file: a pip install, regular
or editable (`make venv`), and colcon.  `python3 -m formation_agent.config` prints the folder:

    formation_agent --ros-args -r __ns:=/agent_2 --params-file agents.params.yaml \\
      --params-file "$(python3 -m formation_agent.config)/turtlebot3.params.yaml"

A regular pip install and colcon also copy them to `<prefix>/share/formation_agent/config/`, where
ROS packages keep such files (`ros2 pkg prefix formation_agent`).  An editable install cannot: pip
installs no data files for it (setuptools' editable wheels hold no `data_files`), which is why
that folder was missing in `.venv`.
"""

from __future__ import annotations

from pathlib import Path

DIRECTORY = Path(__file__).resolve().parent


def params_files() -> dict[str, Path]:
    """The example files by name (`turtlebot3.params.yaml`, ...)."""
    return {path.name: path for path in sorted(DIRECTORY.glob('*.params.yaml'))}
