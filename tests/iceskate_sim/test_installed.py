"""Shipped YAML files by name: an unknown name is refused listing, in a correct plural, those
shipped."""

import pytest

from iceskate_sim.errors import SimulationError
from iceskate_sim.installed import shipped_or_path


def test_an_unknown_study_lists_the_shipped_studies():
    with pytest.raises(SimulationError) as error:
        shipped_or_path('nope', 'iceskate_studies', 'studies', 'study')
    assert str(error.value).startswith("unknown study 'nope'; shipped studies: ")
    assert 'arm_swing' in str(error.value)


def test_an_unknown_scene_lists_the_shipped_scenes():
    with pytest.raises(SimulationError, match="^unknown scene 'nope'; shipped scenes: .*skate"):
        shipped_or_path('nope', 'iceskate_scenes', 'scenes', 'scene')


@pytest.mark.parametrize(('kind', 'kinds'), [('study', 'studies'), ('scene', 'scenes'),
                                             ('key', 'keys'), ('box', 'boxes'),
                                             ('patch', 'patches')])
def test_the_list_of_any_kind_is_in_its_plural(kind, kinds):
    with pytest.raises(SimulationError, match=f'; shipped {kinds}:  \\(or give the path'):
        shipped_or_path('nope', 'no_such_resource', 'nowhere', kind)
