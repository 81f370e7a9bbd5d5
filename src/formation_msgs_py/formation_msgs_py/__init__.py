"""Messages of the formation runtime: ROS-free dataclasses and their encoding over standard Jazzy types."""

from formation_msgs_py.types import SensedState, TriggerInfo

__all__ = ['SensedState', 'TriggerInfo']
