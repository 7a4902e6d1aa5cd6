"""Hostile inputs the tests build: YAML texts that stand for far more than they hold, and
trajectories far longer than a page can show."""

import pathlib
import zipfile

import numpy as np


def alias_bomb(levels: int = 9, width: int = 9) -> str:
    """A YAML flow sequence of ``levels`` anchors, each ``width`` aliases of the one before: a
    few hundred bytes that stand for width ** levels (3.9e8) values."""
    parts = ['&a0 [' + ', '.join(['x'] * width) + ']']
    parts += [f'&a{k} [' + ', '.join([f'*a{k - 1}'] * width) + ']' for k in range(1, levels)]
    return '[' + ', '.join(parts) + ']'


def deep(levels: int = 5000) -> str:
    """A YAML sequence nested ``levels`` deep."""
    return '[' * levels + ']' * levels


def long_trajectory(path: pathlib.Path, samples: int, chunk: int = 1 << 18) -> None:
    """Write a valid ``trajectory.npz`` of ``samples`` samples (t every millisecond, the robot
    standing still) at ``path``, deflated: a few MB on disk, written ``chunk`` rows at a time,
    that stand for ~200 bytes a sample in memory."""
    columns = {'t': ((), np.float64), 'q': ((18,), np.float64), 'mode': ((), np.int64),
               'side': ((), np.int64), 'pivot': ((), np.int64),
               'step_index': ((), np.int64), 'head_target': ((3,), np.float64)}
    with zipfile.ZipFile(path, 'w', zipfile.ZIP_DEFLATED, allowZip64=True,
                         compresslevel=1) as archive:
        for name, (shape, dtype) in columns.items():
            with archive.open(f'{name}.npy', 'w', force_zip64=True) as stream:
                np.lib.format.write_array_header_1_0(stream, {
                    'descr': np.lib.format.dtype_to_descr(np.dtype(dtype)),
                    'fortran_order': False, 'shape': (samples, *shape)})
                for start in range(0, samples, chunk):
                    rows = min(chunk, samples - start)
                    block = (1e-3 * np.arange(start, start + rows) if name == 't'
                             else np.full((rows, *shape), 1 if name == 'mode' else 0, dtype))
                    stream.write(np.ascontiguousarray(block, dtype).tobytes())
