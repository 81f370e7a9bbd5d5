"""The floor under lock-step throughput: bare rclpy round trips between two processes.

`measure(domain_id=..., count=...)` starts two processes on one private ROS domain: a server that
echoes `std_msgs/Float64MultiArray` messages and answers `std_srvs/Trigger` calls, and a client
that times `count` topic round trips (publish, echo, receive) and `count` service calls, with the
QoS of the formation protocol (reliable, transient local, keep last 32) and the same spin-once
loop as the agent nodes. Nothing else runs in either process, so this is what one message hop
costs at least.

    python benchmarks/pingpong.py --domain-id 201 --count 2000
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PING, PONG, SERVICE = '/bench/ping', '/bench/pong', '/bench/sense'


def _executor(kind: str):
    from formation_agent.ros.process import make_executor  # the nodes' own choice of executors

    return make_executor(kind)


def _qos():
    from formation_msgs_py.qos import PROTOCOL_QOS

    return PROTOCOL_QOS


def _serve(seconds: float, kind: str) -> int:
    import rclpy
    from std_msgs.msg import Float64MultiArray
    from std_srvs.srv import Trigger

    rclpy.init()
    try:
        node = rclpy.create_node('bench_pong')
        publisher = node.create_publisher(Float64MultiArray, PONG, _qos())
        node.create_subscription(Float64MultiArray, PING, publisher.publish, _qos())

        def answer(_request, response):
            response.success = True
            response.message = '{"version":1}'
            return response

        node.create_service(Trigger, SERVICE, answer)
        executor = _executor(kind)
        executor.add_node(node)
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
    finally:
        rclpy.try_shutdown()
    return 0


def _ping(count: int, payload: int, kind: str) -> dict:
    import rclpy
    from std_msgs.msg import Float64MultiArray
    from std_srvs.srv import Trigger

    rclpy.init()
    try:
        node = rclpy.create_node('bench_ping')
        received: list[float] = []
        node.create_subscription(Float64MultiArray, PONG, lambda msg: received.append(msg.data[0]), _qos())
        publisher = node.create_publisher(Float64MultiArray, PING, _qos())
        client = node.create_client(Trigger, SERVICE)
        executor = _executor(kind)
        executor.add_node(node)
        started = time.monotonic()
        while not (publisher.get_subscription_count() and client.service_is_ready()):
            executor.spin_once(timeout_sec=0.05)
            if time.monotonic() - started > 60.0:
                raise RuntimeError('pong server not discovered within 60 s')

        def round_trip(seq: int) -> float:
            msg = Float64MultiArray()
            msg.data = [float(seq)] + [0.0] * (payload - 1)
            begin = time.perf_counter()
            publisher.publish(msg)
            while not received or received[-1] != seq:
                executor.spin_once(timeout_sec=1.0)
            return time.perf_counter() - begin

        def call() -> float:
            begin = time.perf_counter()
            future = client.call_async(Trigger.Request())
            while not future.done():
                executor.spin_once(timeout_sec=1.0)
            future.result()
            return time.perf_counter() - begin

        for seq in range(50):  # warm-up
            round_trip(-1 - seq)
            call()
        topic = [round_trip(seq) for seq in range(count)]
        service = [call() for _ in range(count)]
    finally:
        rclpy.try_shutdown()

    def stats(values: list[float]) -> dict:
        ordered = sorted(values)
        return {
            'median_s': statistics.median(ordered),
            'p10_s': ordered[len(ordered) // 10],
            'p90_s': ordered[9 * len(ordered) // 10],
            'mean_s': statistics.fmean(ordered),
        }

    return {
        'count': count,
        'payload_doubles': payload,
        'executor': kind,
        'topic': stats(topic),
        'service': stats(service),
    }


def environment(domain_id: int, log_dir: str) -> dict[str, str]:
    env = dict(os.environ)
    env.update(
        ROS_DOMAIN_ID=str(domain_id),
        ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
        ROS_LOG_DIR=log_dir,
        RMW_IMPLEMENTATION='rmw_fastrtps_cpp',
        PYTHONUNBUFFERED='1',
    )
    return env


def measure(*, domain_id: int, count: int = 2000, payload: int = 10, executor: str = 'single') -> dict:
    """Topic and service round trips between two fresh processes (see the module docstring)."""
    here = str(Path(__file__).resolve())
    with tempfile.TemporaryDirectory(prefix='bench_pingpong_') as logs:
        env = environment(domain_id, logs)
        server = subprocess.Popen(
            [sys.executable, here, '--serve', '600', '--executor', executor],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        try:
            out = subprocess.run(
                [
                    sys.executable,
                    here,
                    '--ping',
                    str(count),
                    '--payload',
                    str(payload),
                    '--executor',
                    executor,
                ],
                env=env,
                capture_output=True,
                text=True,
                timeout=600,
                check=True,
            )
        finally:
            server.terminate()
            try:
                server.wait(timeout=10)
            except subprocess.TimeoutExpired:
                server.kill()
                server.wait()
    # Fast DDS may print to stdout; the result is the last line.
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--domain-id', type=int, default=201)
    parser.add_argument('--count', type=int, default=2000)
    parser.add_argument(
        '--payload', type=int, default=10, help='doubles per message (a TriggerInfo of p = 2 has 10)'
    )
    parser.add_argument(
        '--executor',
        choices=('single', 'events'),
        default='single',
        help="rclpy executor: 'single' (SingleThreadedExecutor, what the nodes use) or 'events' "
        '(rclpy.experimental.EventsExecutor)',
    )
    parser.add_argument('--serve', type=float, default=None, help=argparse.SUPPRESS)
    parser.add_argument('--ping', type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.serve is not None:
        return _serve(args.serve, args.executor)
    if args.ping is not None:
        print(json.dumps(_ping(args.ping, args.payload, args.executor)))
        return 0
    print(
        json.dumps(
            measure(domain_id=args.domain_id, count=args.count, payload=args.payload, executor=args.executor),
            indent=1,
        )
    )
    return 0


if __name__ == '__main__':
    sys.exit(main())
