"""``StagedFiles``: the outputs of a command written under hidden names and renamed to theirs
only once all of them are complete, so that an output folder never holds a file that is partly
written or belongs to a command that did not end (a signal, a failure).
"""

from __future__ import annotations

import os
import pathlib

__all__ = ['StagedFiles']


class StagedFiles:
    """Files of the folder ``out``, each written first as ``.<stem>.partial<suffix>`` (its
    suffix kept: writers choose their format by it).

    Use as a context manager: ``commit`` renames every file to its name, in the order they
    were staged; whatever was not committed is removed on leaving.
    """

    def __init__(self, out: pathlib.Path) -> None:
        self.out = out
        self._staged: dict[pathlib.Path, pathlib.Path] = {}  # final -> staged

    def __enter__(self) -> StagedFiles:
        return self

    def __exit__(self, *exc: object) -> None:
        """Remove the staged files that were not committed."""
        for staged in self._staged.values():
            staged.unlink(missing_ok=True)
        self._staged.clear()

    def __call__(self, name: str) -> pathlib.Path:
        """The path to write the output ``name`` to."""
        final = self.out / name
        staged = self.out / f'.{final.stem}.partial{final.suffix}'
        self._staged[final] = staged
        return staged

    def commit(self) -> list[pathlib.Path]:
        """Rename every staged file to its name; the final paths.

        :raises OSError: when a rename fails (the files not renamed yet are removed on leaving).
        """
        done = []
        for final, staged in list(self._staged.items()):
            os.replace(staged, final)
            del self._staged[final]
            done.append(final)
        return done
