"""Fixtures shared by every test package."""

from __future__ import annotations

import os

import pytest


@pytest.fixture(scope='module')
def ros(request, tmp_path_factory):
    """An rclpy context on the test module's own `DOMAIN_ID`, discovery limited to this machine."""
    import rclpy

    os.environ.setdefault('ROS_LOG_DIR', str(tmp_path_factory.mktemp('ros_log')))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=request.module.DOMAIN_ID)
    try:
        yield context
    finally:
        rclpy.shutdown(context=context)
