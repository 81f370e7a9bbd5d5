"""Robot kinds (ROS-free): the registry (`registry`) and the built-in kinds, registered on import.

- `holonomic`: world-frame velocities (omnidirectional bases, quadrotors in velocity mode);
- `unicycle`: differential drive, steered at a control point l ahead of its axle;
- `car`: a car-like robot (kinematic bicycle: wheelbase L, steering limit φ_max), steered at a
  control point l ahead of its rear axle within its steering constraint |ω| <= |v| tan φ_max / L.

`robot_kind(name)` gives a kind; `KIND_NAMES` (and `KindNames`) list them as they are now.
"""

from formation_agent.core.kinds.car import Car
from formation_agent.core.kinds.holonomic import Holonomic
from formation_agent.core.kinds.registry import (
    KIND_NAMES,
    Geometry,
    KindNames,
    RobotKind,
    register,
    robot_kind,
    unregister,
)
from formation_agent.core.errors import KindError
from formation_agent.core.kinds.unicycle import Unicycle

for _kind in (Holonomic(), Unicycle(), Car()):
    register(_kind)

__all__ = [
    'KIND_NAMES',
    'Geometry',
    'KindError',
    'KindNames',
    'RobotKind',
    'register',
    'robot_kind',
    'unregister',
]
