"""Fast DDS shared-memory files: which belong to a domain."""

from __future__ import annotations

from pathlib import Path


def test_the_port_files_of_a_domain_are_found_by_their_port_numbers(tmp_path):
    from formation_sim.runtime.shm import domain_port_files

    # Domain 231: ports 7400 + 250 * 231 + [0, 250) = [65150, 65400); no test uses it.
    names = ['fastrtps_port65150', 'fastrtps_port65151_el', 'sem.fastrtps_port65399_mutex']
    outside = ['fastrtps_port65400', 'fastrtps_port65149', 'fastrtps_65150', 'fastrtps_port65150x']
    paths = [Path('/dev/shm') / name for name in names + outside]
    try:
        for path in paths:
            path.touch()
        found = {Path(path).name for path in domain_port_files(231)}
        assert found == set(names)
    finally:
        for path in paths:
            path.unlink(missing_ok=True)
