"""The replay's worker threads: order, no nested waits, and work called off as a whole."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading

import numpy as np
import pytest
from pneu_sim.physics import workers


def test_results_come_back_in_the_callers_order():
    out = workers.run_all([lambda i=i: i * i for i in range(17)])
    assert out == [i * i for i in range(17)]
    assert workers.map_tasks(lambda x: -x, range(5)) == [0, -1, -2, -3, -4]


@pytest.mark.skipif(workers.size() < 2, reason="one worker: everything runs in the caller")
def test_a_task_on_the_pool_runs_its_own_replays_itself():
    """A task on a pool thread that asks for more work runs it in its own thread: with every
    pool thread waiting on a barrier no queued task could ever start."""
    n = workers.size()
    barrier = threading.Barrier(n, timeout=60)

    def task() -> list[str]:
        barrier.wait()  # every pool thread is busy here at once
        inner = workers.run_all([lambda: threading.current_thread().name for _ in range(3)])
        return [workers.in_worker(), *inner]

    out = workers.run_all([task for _ in range(n)])
    for res in out:
        assert res[0] is True and len(set(res[1:])) == 1  # all three ran in the one thread


def test_the_first_failure_is_raised_and_calls_the_rest_off():
    """A task that fails stops its siblings at their next replay: a sibling that would loop
    forever ends with Cancelled, and the caller sees the failure, not Cancelled."""
    running = threading.Event()
    ended = []

    def forever() -> None:
        try:
            while True:
                workers.run_all([lambda: None, lambda: None])
                running.set()
        except BaseException as e:
            ended.append(type(e))
            raise

    def fails() -> None:
        running.wait(60)
        raise ValueError("the linear axis has no usable data")

    with pytest.raises(ValueError, match="no usable data"):
        workers.concurrently([forever, fails])
    assert running.is_set() and ended == [workers.Cancelled]


def test_concurrent_results_in_order():
    assert workers.concurrently([lambda i=i: i + 1 for i in range(4)]) == [1, 2, 3, 4]


def test_an_interrupted_caller_stops_every_thread(tmp_path):
    """A real SIGINT while two threads replay forever: the process ends with
    KeyboardInterrupt (had a thread kept running, the interpreter would wait for it at exit
    and the process would never end)."""
    script = textwrap.dedent(
        """
        import sys
        import numpy as np
        from pneu_sim.physics import workers
        from pneu_sim.physics.plant_file import load_plant
        from pneu_sim.physics import replay as rp

        plant = load_plant()
        prm = rp.replay_params(plant)
        st = rp.replay_state(prm, plant, x=0.0, v=0.0, p_c1=2e5, p_c2=2e5, theta=0.0,
                             omega=0.0, p_m1=1.2e5, u_linear=5.0, u_rotary=5.0)
        u = np.full(4000, 6.0)

        def forever(tag):
            n = 0
            while True:
                rp.replay_segments(np.array([st, st]), prm, u, u, np.array([0, 0]),
                                   np.array([4000, 4000]))
                n += 1
                if n == 2:
                    print(tag, flush=True)

        try:
            workers.concurrently([lambda: forever("a"), lambda: forever("b")])
        except KeyboardInterrupt:
            print("interrupted", flush=True)
            sys.exit(130)
        """
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", script],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )
    seen = {proc.stdout.readline().strip(), proc.stdout.readline().strip()}
    assert seen == {"a", "b"}  # both threads are replaying
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=300)  # a hang guard, not a speed bound
    assert proc.returncode == 130, err
    assert out.strip() == "interrupted"


@pytest.mark.parametrize("axes", ["both", "linear", "rotary"])
def test_split_replays_are_the_serial_ones_to_the_bit(axes):
    """replay_segments split over the workers (enough periods for every worker) gives each
    segment's replay() bits, and the same kept states."""
    from pneu_sim.physics import replay as rp
    from pneu_sim.physics.plant_file import load_plant

    plant = load_plant()
    prm = rp.replay_params(plant)
    rng = np.random.default_rng(3)
    n = 20_000
    ul = 5.0 + np.repeat(rng.uniform(-1.2, 1.2, n // 50), 50)
    ur = 5.5 + np.repeat(rng.uniform(-0.2, 0.5, n // 50), 50)
    pc = None
    if axes == "rotary":
        pc = np.column_stack([np.linspace(2e5, 3e5, n), np.linspace(3e5, 2e5, n)])
    starts = np.array([0, 3000, 7000, 7000, 15000, 19990])
    lengths = np.array([2500, 4000, 1000, 6000, 4999, 0])
    assert lengths.sum() >= workers.size() * rp._MIN_CHUNK  # every worker gets a chunk
    kw = dict(v=0.0, p_c1=2e5, p_c2=2.2e5, theta=0.0, p_m1=1.5e5, u_linear=5.0, u_rotary=5.0)
    states = np.array(
        [rp.replay_state(prm, plant, x=0.01 * k, omega=10.0 * k, **kw) for k in range(len(starts))]
    )
    trace = np.empty((int(lengths.sum()), states.shape[1]))
    batch = rp.replay_segments(states, prm, ul, ur, starts, lengths, axes, pc, trace)
    rows = np.concatenate(([0], np.cumsum(lengths)))
    for s, (a, m) in enumerate(zip(starts, lengths)):
        st = states[s].copy()
        p_c = None if pc is None else pc[a : a + m]
        one = rp.replay(st, prm, ul[a : a + m], ur[a : a + m], axes, p_c)
        assert np.array_equal(batch[rows[s] : rows[s + 1]], one)
        if m:
            assert np.array_equal(trace[rows[s]], states[s])


def test_a_group_takes_work_as_it_becomes_ready():
    """Threads started one after another (a draw's fits while the next draw is excited) run
    beside the caller; their results come back in the order they were started."""
    gate = threading.Event()
    with workers.Group() as group:
        group.start([lambda: (gate.wait(60), "first")[1]])
        group.start([lambda: "second", lambda: "third"])
        gate.set()  # the first thread was running while the caller went on
        assert group.results() == ["first", "second", "third"]


def test_a_failure_in_the_callers_thread_calls_the_group_off():
    """An error in the caller between two starts (an excitation that fails) stops the
    threads already started: leaving the block waits for them, and they end Cancelled."""
    ended = []

    def forever() -> None:
        try:
            while True:
                workers.run_all([lambda: None, lambda: None])
        except BaseException as e:
            ended.append(type(e))
            raise

    with pytest.raises(RuntimeError, match="excitation"), workers.Group() as group:
        group.start([forever])
        raise RuntimeError("the excitation failed")
    assert ended == [workers.Cancelled]
