"""The ROS-free parts of the graph launcher: the nodes' parameter files and their run token,
real-time scheduling of the nodes."""

import os
import re

import pytest
import yaml

from iceskate_bringup.graph import graph_nodes, realtime_scheduling
from iceskate_sim.errors import SimulationError


def test_every_node_of_a_run_gets_its_token_in_a_file_only_the_user_reads(tmp_path):
    """One new token per run, the same in every node's parameter file; the files are 0600."""
    def tokens(out):
        specs = graph_nodes('skate', out)
        found = set()
        for spec in specs:
            assert spec.parameter_file.stat().st_mode & 0o777 == 0o600, spec.parameter_file
            (block,) = yaml.safe_load(spec.parameter_file.read_text()).values()
            found.add(block['ros__parameters']['run_token'])
        assert len(specs) == 3
        return found
    (first,) = tokens(tmp_path / 'a')
    (second,) = tokens(tmp_path / 'b')
    assert re.fullmatch('[0-9a-f]{32}', first) and first != second


def test_priority_zero_leaves_the_scheduling_as_it_is():
    before = (os.sched_getscheduler(0), os.sched_getparam(0))
    with realtime_scheduling(0):
        assert (os.sched_getscheduler(0), os.sched_getparam(0)) == before


@pytest.mark.parametrize('priority', [-1, 100])
def test_a_priority_out_of_range_is_refused_naming_the_range(priority):
    with pytest.raises(SimulationError, match=rf'0 \(off\) or 1\.\.99, got {priority}'), \
            realtime_scheduling(priority):
        pytest.fail('the block ran')


def test_missing_permission_is_a_clear_error(monkeypatch):
    def refuse(pid, policy, param):
        raise PermissionError(1, 'Operation not permitted')
    monkeypatch.setattr(os, 'sched_setscheduler', refuse)
    with pytest.raises(SimulationError, match='rt_priority 10: real-time scheduling') as info, \
            realtime_scheduling(10):
        pytest.fail('the block ran')
    assert 'Operation not permitted' in str(info.value) and 'rtprio' in str(info.value)


def test_the_block_runs_under_sched_fifo_and_the_old_policy_comes_back(needs_fifo):
    before = (os.sched_getscheduler(0), os.sched_getparam(0))
    with pytest.raises(RuntimeError), realtime_scheduling(12):
        assert os.sched_getscheduler(0) == os.SCHED_FIFO
        assert os.sched_getparam(0).sched_priority == 12
        raise RuntimeError('leaves the block')
    assert (os.sched_getscheduler(0), os.sched_getparam(0)) == before
