"""Files the workspace's packages install, ``share/<package>/...``, found through the ament
index (``ament_index_python``) as ROS finds them; shipped YAML files (scenes, studies) by name.
"""

from __future__ import annotations

import pathlib

from ament_index_python import PackageNotFoundError, get_package_share_path, get_resources

from iceskate_sim.errors import InputRefused, SimulationError


def share_path(package: str, *parts: str) -> pathlib.Path:
    """``share/<package>/<parts>`` of an installed package (the path may not exist).

    :raises SimulationError: if the package is not installed (``make setup`` builds ros_ws).
    """
    try:
        return get_package_share_path(package).joinpath(*parts)
    except PackageNotFoundError:
        raise SimulationError(f'package {package} is not installed (no {package} in '
                              'AMENT_PREFIX_PATH: build ros_ws with make setup and source '
                              'env.sh)') from None


def shipped_files(resource: str, folder: str) -> dict[str, pathlib.Path]:
    """Name -> ``share/<package>/<folder>/<name>.yaml`` of the packages registered under the
    ament index's ``resource`` (the first package, by name, wins a name)."""
    found: dict[str, pathlib.Path] = {}
    for package, prefix in sorted(get_resources(resource).items()):
        for path in sorted((pathlib.Path(prefix) / 'share' / package / folder).glob('*.yaml')):
            found.setdefault(path.stem, path)
    return found


def _plural(noun: str) -> str:
    """The plural of an English noun of a kind of file (scene -> scenes, study -> studies)."""
    if noun.endswith('y') and noun[-2:-1] not in ('', *'aeiou'):
        return noun[:-1] + 'ies'
    return noun + ('es' if noun.endswith(('s', 'x', 'z', 'ch', 'sh')) else 's')


def shipped_or_path(name_or_path: str | pathlib.Path, resource: str, folder: str,
                    what: str) -> pathlib.Path:
    """The shipped YAML file of a name (``shipped_files``), or the path itself (one with a
    suffix or a folder), which must name a .yaml or .yml file: no other file is read as one
    (nor its content quoted in an error).

    :raises InputRefused: for a name none ships, listing those shipped; a path of another
        kind of file.
    """
    path = pathlib.Path(name_or_path)
    if path.suffix or len(path.parts) > 1:
        if path.suffix.lower() not in ('.yaml', '.yml'):
            raise InputRefused(f'{what} {str(name_or_path)!r} is neither a shipped {what} '
                               'name nor the path of a .yaml file')
        return path
    shipped = shipped_files(resource, folder)
    if path.name in shipped:
        return shipped[path.name]
    raise InputRefused(f'unknown {what} {str(name_or_path)!r}; shipped {_plural(what)}: '
                       f'{", ".join(shipped)} (or give the path of a YAML file)')
