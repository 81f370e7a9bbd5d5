"""The team's state at a run's sample times, in memory or in a trajectory folder on disk (ROS-free).

A run samples the whole state at every event time and on a regular grid
(`formation_sim.sim.engine.Sampler`). Small runs keep the samples in memory; `formation simulate`
streams them into its run folder as they are produced (`TrajectoryWriter`), so that its memory
is O(n + samples) instead of O(samples × n), and reads them back memory-mapped. Either way they
are a `Samples`, the store every `RunRecord` holds, and `load_trajectory` is the one reader of a
run folder's samples.

Trajectory folder `trajectory/` of a run folder: NumPy `.npy` files (format 1.0, little-endian,
C order), each readable alone, lazily, with `np.load(path, mmap_mode='r')`; file (shape, type):
what it holds:

- `agent_ids.npy` ((n,) int64): row k of every state is agent agent_ids[k]
- `times.npy` ((K,) float64): the sample times, increasing
- `positions.npy` ((K, n, p) float64): x at each sample time
- `velocities.npy` ((K, n, p) float64): q at each sample time (double integrators only)
- `edge_maxima.npy` ((m,) float64): only when not every event time is a sample: per edge (the
  scenario's order), the largest ‖x_i − x_j‖ at t = 0, the horizon and its two agents' triggering
  times (`EdgeLengths`)

While a run goes on the folder is `trajectory.incomplete/`: the states are appended as they come,
after a header of fixed size that says 0 rows. At the end the headers are rewritten with the row
count, every file is flushed to the device, and the folder is renamed `trajectory/`. A run killed
midway thus leaves `trajectory.incomplete/` (its `.npy` files read as empty), never a
`trajectory/` cut short, and `load_trajectory` refuses it by name. Runs written before this format
hold `trajectory.npz` (arrays `agent_ids`, `times`, `positions`[, `velocities`]), which
`load_trajectory` reads as well (into memory).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from formation_agent.core import compiled
from formation_sim.sim.errors import TrajectoryError

TRAJECTORY_DIR = 'trajectory'
INCOMPLETE_DIR = 'trajectory.incomplete'
LEGACY_TRAJECTORY_FILE = 'trajectory.npz'
POSITIONS, VELOCITIES, TIMES, AGENT_IDS, EDGE_MAXIMA = (
    'positions',
    'velocities',
    'times',
    'agent_ids',
    'edge_maxima',
)

_HEADER_BYTES = 128  # magic, version, length and the padded dictionary: room for any shape, 64-aligned data
_BLOCK_VALUES = 1 << 20  # numbers read at a time when scanning all samples (8 MiB)
_EDGE_BLOCK_VALUES = (
    1 << 15
)  # edge components computed at a time (256 kB: they stay in the CPU's cache, 2-3x faster)
_WRITE_BUFFER = 1 << 20


# ------------------------------------------------------------------------------------- samples


@dataclass(frozen=True, kw_only=True, eq=False)
class Samples:
    """The state at K sample times: arrays in memory, or memory-mapped files of a trajectory folder
    (`path`)."""

    times: np.ndarray  # (K,) increasing
    positions: np.ndarray  # (K, n, p)
    velocities: np.ndarray | None = None  # (K, n, p) for double integrators
    edge_maxima: np.ndarray | None = None  # (m,) see the module docstring; None: every event time is a sample
    path: Path | None = None  # the trajectory folder the arrays are mapped from

    @classmethod
    def from_rows(
        cls, times, positions, velocities=None, *, edge_maxima: np.ndarray | None = None
    ) -> Samples:
        """In memory, from sequences of rows (lists of (n, p) arrays as a sampler collects them)."""
        return cls(
            times=np.array(times, dtype=float),
            positions=np.array(positions, dtype=float),
            velocities=np.array(velocities, dtype=float)
            if velocities is not None and len(velocities)
            else None,
            edge_maxima=edge_maxima,
        )

    def __len__(self) -> int:
        return len(self.times)

    def blocks(self, *, values: int = _BLOCK_VALUES) -> Iterator[tuple[np.ndarray, np.ndarray | None]]:
        """(positions, velocities) of consecutive rows, `values` numbers at a time.

        Samples on disk are read from their files block by block (not through the mapping, whose
        pages would stay resident): a pass over every sample needs memory for one block only.
        """
        count = len(self.times)
        row = max(1, int(np.prod(self.positions.shape[1:])))
        step = max(1, values // row)
        on_disk = self.path is not None  # the arrays map whole files (read_trajectory)
        for start in range(0, count, step):
            stop = min(count, start + step)
            yield (
                _rows(self.positions, start, stop, from_file=on_disk),
                None if self.velocities is None else _rows(self.velocities, start, stop, from_file=on_disk),
            )


def _rows(array: np.ndarray, start: int, stop: int, *, from_file: bool) -> np.ndarray:
    if not (from_file and isinstance(array, np.memmap)):
        return array[start:stop]
    shape = (stop - start, *array.shape[1:])
    row_bytes = int(np.prod(array.shape[1:])) * array.itemsize
    with open(array.filename, 'rb') as handle:
        handle.seek(array.offset + start * row_bytes)
        block = np.fromfile(handle, dtype=array.dtype, count=int(np.prod(shape)))
    if block.size != np.prod(shape):
        raise TrajectoryError(f'{array.filename}: cut short: rows {start}..{stop} are not all there')
    return block.reshape(shape)


# ----------------------------------------------------------------------------------- edge lengths


def squared_lengths(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """‖a − b‖² over the last axis, summed in `np.linalg.norm`'s order, so that its square root is
    norm's very float: left to right below 8 components, numpy's pairwise summation from 8 on."""
    dimension = a.shape[-1]
    if dimension >= 8:
        difference = np.ascontiguousarray(a - b)  # summed along memory, as norm sums its rows
        return np.add.reduce(difference * difference, axis=-1)
    total = None
    for c in range(dimension):
        component = a[..., c] - b[..., c]
        component *= component
        if total is None:
            total = component
        else:
            total += component
    return total


class EdgeLengths:
    """The largest length ‖x_i − x_j‖ of every edge over the states shown to it (the summary's `max_length`).

    `add_states` takes whole states (every edge); `add_edges` only some edges (`edges_of` agents). For
    single integrators an edge's length is convex between its two agents' triggering times, so
    the states at t = 0, the horizon and those triggering times give its exact maximum; the engine
    uses that when it does not keep every event time as a sample (`edge_maxima` of `Samples`).
    """

    def __init__(self, scenario) -> None:
        self.heads, self.tails, _ = scenario.edge_indices()
        self.squared = np.zeros(len(self.heads))
        self._incident: list[np.ndarray] | None = None
        # (start, incident, heads, tails) as int64: incident[start[k]:start[k + 1]] the edges of agent row k
        self._csr: tuple[np.ndarray, ...] | None = None
        self._n = scenario.n

    def add_states(self, positions: np.ndarray) -> None:
        """States of shape (rows, n, p): every edge at every row."""
        # Agent-major layout per component: gathering the edges' ends is then contiguous per row.
        by_component = np.ascontiguousarray(np.moveaxis(positions, -1, 1))  # (rows, p, n)
        squared = squared_lengths(
            np.moveaxis(np.take(by_component, self.heads, axis=2), 1, -1),
            np.moveaxis(np.take(by_component, self.tails, axis=2), 1, -1),
        )
        np.maximum(self.squared, squared.max(axis=0), out=self.squared)

    def edges_of(self, rows) -> np.ndarray:
        """Indices of the edges with an end at one of these agent rows."""
        if self._incident is None:
            ends = np.concatenate([self.heads, self.tails])
            edges = np.concatenate([np.arange(len(self.heads))] * 2)
            order = np.argsort(ends, kind='stable')
            bounds = np.searchsorted(ends[order], np.arange(self._n + 1))
            self._incident = [edges[order[bounds[k] : bounds[k + 1]]] for k in range(self._n)]
        return np.unique(np.concatenate([self._incident[k] for k in rows]))

    def add_rows(self, rows: list[int], positions: np.ndarray) -> None:
        """The edges with an end at one of these agent rows, from the state `positions` ((n, p)): as
        `add_edges(edges_of(rows), ...)`, in one compiled pass where the compiled core runs (the same
        floats: the squared lengths summed as `squared_lengths` sums them, kept by numpy.maximum's rule)."""
        fast = compiled.edge_watch()
        if fast is not None:
            if self._csr is None:
                ends = np.concatenate([self.heads, self.tails])
                order = np.argsort(ends, kind='stable')
                incident = np.concatenate([np.arange(len(self.heads))] * 2)[order].astype(np.int64)
                start = np.searchsorted(ends[order], np.arange(self._n + 1)).astype(np.int64)
                self._csr = (start, incident, self.heads.astype(np.int64), self.tails.astype(np.int64))
            if fast(positions, list(rows), *self._csr, self.squared):
                return
        edges = self.edges_of(rows)
        self.add_edges(edges, positions[self.heads[edges]], positions[self.tails[edges]])

    def add_edges(self, edges: np.ndarray, head_positions: np.ndarray, tail_positions: np.ndarray) -> None:
        """The given edges, with their heads' and tails' positions (each (len(edges), p))."""
        squared = squared_lengths(head_positions, tail_positions)
        self.squared[edges] = np.maximum(self.squared[edges], squared)

    @property
    def maxima(self) -> np.ndarray:
        return np.sqrt(self.squared)


def edge_maxima(scenario, samples: Samples) -> np.ndarray:
    """Per edge, the largest ‖x_i − x_j‖ over every sample (and over `samples.edge_maxima`), in one
    pass of bounded memory; the same floats as `np.linalg.norm` sample by sample."""
    lengths = EdgeLengths(scenario)
    rows = max(1, _EDGE_BLOCK_VALUES // max(1, len(lengths.heads) * scenario.dimension))
    for positions, _ in samples.blocks():
        for start in range(0, len(positions), rows):
            lengths.add_states(positions[start : start + rows])
    maxima = lengths.maxima
    if samples.edge_maxima is not None:
        maxima = np.maximum(maxima, samples.edge_maxima)
    return maxima


# ------------------------------------------------------------------------------------ the format


def _npy_header(dtype: np.dtype, shape: tuple[int, ...]) -> bytes:
    """An .npy format 1.0 header of exactly _HEADER_BYTES bytes (padded with spaces, as the format allows)."""
    text = repr(
        {
            'descr': np.lib.format.dtype_to_descr(np.dtype(dtype)),
            'fortran_order': False,
            'shape': tuple(shape),
        }
    )
    length = _HEADER_BYTES - 10
    if len(text) + 1 > length:  # pragma: no cover - shapes of a few integers fit in 118 characters
        raise TrajectoryError(f'shape {shape} does not fit the trajectory header')
    return b'\x93NUMPY\x01\x00' + struct.pack('<H', length) + (text.ljust(length - 1) + '\n').encode('latin1')


def _fsync_folder(folder: Path) -> None:
    descriptor = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


class TrajectoryWriter:
    """Streams the samples of a run into `run_dir/trajectory.incomplete/`; `close` completes it as
    `trajectory/`.

    Memory: the sample times only (8 bytes a sample); the states go to the files as they come.
    """

    def __init__(self, run_dir: str | Path, *, agent_ids, dimension: int, velocities: bool) -> None:
        self.run_dir = Path(run_dir)
        self.folder = self.run_dir / INCOMPLETE_DIR
        self.agent_ids = np.asarray(agent_ids, dtype=np.int64)
        self.row_shape = (len(self.agent_ids), int(dimension))
        self.count = 0
        self._files = {}
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.folder.mkdir()  # an existing one is another writer's (a run folder is claimed empty)
        try:
            for name in (POSITIONS, VELOCITIES) if velocities else (POSITIONS,):
                handle = open(self.folder / f'{name}.npy', 'wb', buffering=_WRITE_BUFFER)  # noqa: SIM115 - closed in close/abandon
                self._files[name] = handle
                handle.write(_npy_header(np.float64, (0, *self.row_shape)))
        except BaseException:
            self.abandon()
            raise

    def append(self, positions: np.ndarray, velocities: np.ndarray | None = None) -> None:
        """One sample's state, (n, p) each (or several, (rows, n, p))."""
        rows = self._write(POSITIONS, positions)
        if velocities is not None:
            self._write(VELOCITIES, velocities)
        self.count += rows

    def _write(self, name: str, values: np.ndarray) -> int:
        array = np.ascontiguousarray(values, dtype='<f8')
        if array.shape[-2:] != self.row_shape:
            raise ValueError(f'{name}: a state of shape {array.shape[-2:]}, expected {self.row_shape}')
        self._files[name].write(memoryview(array).cast('B'))
        return 1 if array.ndim == 2 else array.shape[0]

    def close(self, times, *, edge_maxima: np.ndarray | None = None) -> Samples:
        """Complete the trajectory with its sample times and rename it `trajectory/`; its samples,
        memory-mapped."""
        times = np.asarray(times, dtype='<f8')
        if times.shape != (self.count,):
            self.abandon()
            raise ValueError(f'{len(times)} sample times for {self.count} states')
        try:
            for handle in self._files.values():
                handle.flush()
                handle.seek(0)
                handle.write(_npy_header(np.float64, (self.count, *self.row_shape)))
                handle.flush()
                os.fsync(handle.fileno())  # the data reach the device before the name says complete
                handle.close()
            extras = {TIMES: times, AGENT_IDS: self.agent_ids}
            if edge_maxima is not None:
                extras[EDGE_MAXIMA] = np.asarray(edge_maxima, dtype='<f8')
            for name, array in extras.items():
                with open(self.folder / f'{name}.npy', 'wb') as handle:
                    np.save(handle, array)
                    handle.flush()
                    os.fsync(handle.fileno())
            _fsync_folder(self.folder)
            final = self.run_dir / TRAJECTORY_DIR
            if final.exists():  # a record written again into its folder: the old samples give way
                shutil.rmtree(final)
            self.folder.rename(final)
            _fsync_folder(self.run_dir)
        except OSError as error:
            self.abandon()
            raise OSError(error.errno, error.strerror, str(self.folder)) from error
        except BaseException:
            self.abandon()
            raise
        return read_trajectory(final)

    def abandon(self) -> None:
        """Close the files, leaving what was written as `trajectory.incomplete/` (a run that stopped)."""
        for handle in self._files.values():
            with contextlib.suppress(OSError):
                handle.close()
        self._files = {}


def write_trajectory(samples: Samples, run_dir: str | Path, *, agent_ids) -> Samples:
    """Write in-memory `samples` as `run_dir/trajectory/` (through `trajectory.incomplete/`); the written
    samples."""
    velocities = samples.velocities is not None
    writer = TrajectoryWriter(
        run_dir, agent_ids=agent_ids, dimension=samples.positions.shape[2], velocities=velocities
    )
    try:
        for positions, velocity_rows in samples.blocks():
            writer.append(positions, velocity_rows)
        return writer.close(samples.times, edge_maxima=samples.edge_maxima)
    except BaseException:
        writer.abandon()
        discard_incomplete(run_dir)  # the samples are still in memory: nothing half-written stays
        raise


def discard_incomplete(run_dir: str | Path) -> None:
    """Remove the `trajectory.incomplete/` of a run that failed (its samples belong to no result)."""
    shutil.rmtree(Path(run_dir) / INCOMPLETE_DIR, ignore_errors=True)


# ------------------------------------------------------------------------------------- reading


def _load_npy(path: Path, *, mmap: bool) -> np.ndarray:
    try:
        return np.load(path, mmap_mode='r' if mmap else None, allow_pickle=False)
    except FileNotFoundError:
        raise TrajectoryError(f'{path}: missing') from None
    except (OSError, ValueError, EOFError, SyntaxError) as error:
        # A file shorter than its header says ("mmap length is greater than file size"), a broken header
        raise TrajectoryError(f'{path}: cannot be read as a trajectory array: {error}') from None


def read_trajectory(folder: str | Path) -> Samples:
    """The samples of a trajectory folder, the states memory-mapped; checked for consistent shapes."""
    folder = Path(folder)
    times = np.array(_load_npy(folder / f'{TIMES}.npy', mmap=False), dtype=float)
    agent_ids = _load_npy(folder / f'{AGENT_IDS}.npy', mmap=False)
    positions = _load_npy(folder / f'{POSITIONS}.npy', mmap=True)
    velocities = (
        _load_npy(folder / f'{VELOCITIES}.npy', mmap=True)
        if (folder / f'{VELOCITIES}.npy').exists()
        else None
    )
    maxima_path = folder / f'{EDGE_MAXIMA}.npy'
    maxima = np.array(_load_npy(maxima_path, mmap=False), dtype=float) if maxima_path.exists() else None
    expected = (len(times), len(agent_ids))
    if times.ndim != 1 or positions.ndim != 3 or positions.shape[:2] != expected:
        raise TrajectoryError(
            f'{folder}: {len(times)} sample times and {len(agent_ids)} agents, but positions of shape '
            f'{positions.shape}'
        )
    if velocities is not None and velocities.shape != positions.shape:
        raise TrajectoryError(
            f'{folder}: velocities of shape {velocities.shape}, positions {positions.shape}'
        )
    if len(times) == 0:
        raise TrajectoryError(f'{folder}: holds no sample')
    return Samples(times=times, positions=positions, velocities=velocities, edge_maxima=maxima, path=folder)


def load_trajectory(run_dir: str | Path) -> Samples | None:
    """The samples of a run folder: `trajectory/` (memory-mapped) or an older run's `trajectory.npz`;
    None if it has neither. Raises TrajectoryError for one that was never completed or is damaged."""
    run_dir = Path(run_dir)
    if (run_dir / TRAJECTORY_DIR).is_dir():
        return read_trajectory(run_dir / TRAJECTORY_DIR)
    legacy = run_dir / LEGACY_TRAJECTORY_FILE
    if legacy.is_file():
        try:
            with np.load(legacy, allow_pickle=False) as data:
                return Samples(
                    times=np.array(data[TIMES], dtype=float),
                    positions=np.array(data[POSITIONS], dtype=float),
                    velocities=np.array(data[VELOCITIES], dtype=float) if VELOCITIES in data else None,
                )
        except (OSError, ValueError, KeyError, EOFError) as error:
            raise TrajectoryError(f'{legacy}: cannot be read: {error}') from None
    if (run_dir / INCOMPLETE_DIR).is_dir():
        raise TrajectoryError(
            f'{run_dir / INCOMPLETE_DIR}: the run stopped before its trajectory was complete (it was '
            'killed or failed while writing it); its samples are not a whole run'
        )
    return None


def header_shape(path: str | Path) -> tuple[int, ...]:
    """The shape an .npy file's header states (for tests and tools reading an incomplete trajectory)."""
    with open(path, 'rb') as handle:
        np.lib.format.read_magic(handle)
        shape, _, _ = np.lib.format.read_array_header_1_0(handle)
    return tuple(shape)
