"""Live tools on a ROS graph: `replay` (a bag published again), `graph` (its topics and messages)."""
