"""What the parent process of a run does: plan it, write its inputs, start, watch and stop its children.

It starts the node programs by their module names and agrees with them through
`formation_sim.runtime.contract`; it imports no module of `formation_sim.runtime.nodes`
(tests/test_layout.py), so that it starts without rclpy.
"""
