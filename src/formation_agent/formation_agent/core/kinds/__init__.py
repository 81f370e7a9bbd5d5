"""Robot kinds (ROS-free): the registry (`registry`) and the built-in kinds, registered on import.

- `holonomic`: world-frame velocities (omnidirectional bases, quadrotors in velocity mode);
- `unicycle`: differential drive, steered at a control point l ahead of its axle;
- `car`: a car-like robot (kinematic bicycle: wheelbase L, steering limit φ_max), steered at a
  control point l ahead of its rear axle within its steering constraint |ω| <= |v| tan φ_max / L.

`robot_kind(name)` gives a kind; `KIND_NAMES` (and `KindNames`) list them as they are now.  Each
kind declares its shape parameters once (`shape`: `ShapeParameter`, `Geometry`), among them its
footprint radius; `control_point_separation` and `default_min_separation` turn footprints into the
separation between control points the safety layer keeps (docs/ROBOTS.md, "Footprints").
"""

from formation_agent.core.errors import KindError, ShapeError
from formation_agent.core.kinds.car import Car
from formation_agent.core.kinds.holonomic import Holonomic
from formation_agent.core.kinds.registry import (
    FOOTPRINT_RADIUS,
    KIND_NAMES,
    SEPARATION_MARGIN,
    KindNames,
    RobotKind,
    control_point_separation,
    default_min_separation,
    register,
    robot_kind,
    unregister,
)
from formation_agent.core.kinds.shape import Geometry, ShapeParameter
from formation_agent.core.kinds.unicycle import Unicycle

for _kind in (Holonomic(), Unicycle(), Car()):
    register(_kind)

__all__ = [
    'FOOTPRINT_RADIUS',
    'KIND_NAMES',
    'SEPARATION_MARGIN',
    'Geometry',
    'KindError',
    'KindNames',
    'RobotKind',
    'ShapeError',
    'ShapeParameter',
    'control_point_separation',
    'default_min_separation',
    'register',
    'robot_kind',
    'unregister',
]
