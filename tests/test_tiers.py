"""The order the test files run in (tests/conftest.py): heaviest first by the worker-seconds in tests/durations.json,
handed out in that order by xdist's LoadFile scheduler (run here on two fake workers, with made-up durations, so
nothing is compiled), and the table's refresh."""

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

TESTS = Path(__file__).parent


@pytest.fixture(scope="module")
def conftest(request):
    """tests/conftest.py as pytest loaded it (importing it again would run its XLA flag probe again)."""
    path = TESTS / "conftest.py"
    (module,) = [p for p in request.config.pluginmanager.get_plugins() if getattr(p, "__file__", None) == str(path)]
    return module


def item(nodeid, slow=False):
    """What heaviest_first reads of a pytest item: its node id and whether it is marked slow."""
    return SimpleNamespace(nodeid=nodeid, get_closest_marker=lambda name: object() if slow and name == "slow" else None)


def ids(items):
    return [i.nodeid for i in items]


TABLE = {"fast": {"tests/test_a.py": 10, "tests/test_b.py": 100, "tests/test_server.py": 30, "tests/test_live.py": 5},
         "slow": {"tests/test_a.py": 500}}


def test_files_are_ordered_by_their_cost_in_the_tiers_selected(conftest):
    items = [item("tests/test_a.py::f1"), item("tests/test_a.py::s1", slow=True), item("tests/test_a.py::f2"),
             item("tests/test_b.py::f1"), item("tests/test_b.py::f2"), item("tests/test_c.py::f1"),
             item("tests/test_live.py::f1"), item("tests/test_live.py::f2"), item("tests/test_server.py::f1")]
    # a: 10 + 500 (its slow test); b: 100; c: not in the table, DEFAULT_FILE_S; the server's and the live drives'
    # files are one unit of work (ONE_WORKER): 30 + 5 = 35, its items together in their own order
    assert conftest.DEFAULT_FILE_S > 35
    assert ids(conftest.heaviest_first(items, TABLE)) == [
        "tests/test_a.py::f1", "tests/test_a.py::s1", "tests/test_a.py::f2", "tests/test_b.py::f1",
        "tests/test_b.py::f2", "tests/test_c.py::f1", "tests/test_live.py::f1", "tests/test_live.py::f2",
        "tests/test_server.py::f1"]
    fast = [i for i in items if i.get_closest_marker("slow") is None]  # the fast tier: a costs only 10
    assert [n.split("::")[0] for n in ids(conftest.heaviest_first(fast, TABLE))] == [
        "tests/test_b.py", "tests/test_b.py", "tests/test_c.py", "tests/test_live.py", "tests/test_live.py",
        "tests/test_server.py", "tests/test_a.py", "tests/test_a.py"]
    empty = {"fast": {}, "slow": {}}  # no table: each file in each tier DEFAULT_FILE_S, so the unit of two files
    assert ids(conftest.heaviest_first(fast, empty)) == ids(fast[5:]) + ids(fast[:5])  # first, then as collected


class FakeConfig:
    """What xdist's LoadFile scheduler reads of pytest's config: two workers, ``--dist loadfile``."""

    def __init__(self, reorder):
        self.option = SimpleNamespace(loadscopereorder=reorder, dist="loadfile")

    def getvalue(self, name):
        return {"dist": "loadfile", "tx": ["2*popen"]}[name]


class FakeWorker:
    shutting_down = False

    def __init__(self, name):
        self.gateway = SimpleNamespace(id=name)
        self.sent = []

    def send_runtest_some(self, indices):
        self.sent.extend(indices)

    def shutdown(self):
        self.shutting_down = True


def run_on_two_workers(scheduler, collection, seconds):
    """Play the scheduler's protocol with two workers that take ``seconds[nodeid]`` per test: each runs what it
    was sent in order and reports every test as done. Returns (each worker's finishing time, the files each
    started with)."""
    workers = [FakeWorker("gw0"), FakeWorker("gw1")]
    for w in workers:
        scheduler.add_node(w)
    for w in workers:
        scheduler.add_node_collection(w, collection)
    scheduler.schedule()
    firsts = [collection[w.sent[0]].split("::")[0] for w in workers]
    clock, done = [0.0, 0.0], [0, 0]
    while True:
        ready = [(clock[k] + seconds[collection[w.sent[done[k]]]], k) for k, w in enumerate(workers)
                 if done[k] < len(w.sent)]
        if not ready:
            break
        t, k = min(ready)
        clock[k], index = t, workers[k].sent[done[k]]
        done[k] += 1
        scheduler.mark_test_complete(workers[k], index)
    assert sorted(workers[0].sent + workers[1].sent) == list(range(len(collection)))  # each test once
    return clock, firsts


def test_xdist_hands_out_the_heaviest_files_first_and_the_workers_finish_together(conftest):
    """A suite like ours: one file of one 300 s test (the README's examples), two of 20 x 10 s, and many small
    files of many quick tests. xdist's own order (by count of tests) starts the one-test file last, and one
    worker then runs it alone; in the collection's order, heaviest first, the workers finish within the
    largest small file of each other."""
    from xdist.scheduler import LoadFileScheduling

    files = {"tests/test_readme.py": [300.0], "tests/test_big1.py": [10.0] * 20, "tests/test_big2.py": [10.0] * 20}
    files.update({f"tests/test_small{i}.py": [1.0] * (30 + i) for i in range(8)})
    seconds = {f"{f}::t{j}": s for f, tests in files.items() for j, s in enumerate(tests)}
    items = [item(n) for n in sorted(seconds)]  # the collection's order: by name
    table = {"fast": {f: sum(tests) for f, tests in files.items()}, "slow": {}}
    ours = ids(conftest.heaviest_first(items, table))

    config = FakeConfig(reorder=True)
    (finish, firsts) = run_on_two_workers(conftest.pytest_xdist_make_scheduler(config, None), ours, seconds)
    assert config.option.loadscopereorder is False  # our scheduler keeps the collection's order
    assert sorted(firsts) == ["tests/test_big1.py", "tests/test_readme.py"]  # one of the two heaviest each
    total, largest_small = sum(seconds.values()), 30 + 7
    assert abs(finish[0] - finish[1]) <= largest_small and max(finish) <= total / 2 + largest_small

    xdist_order, _ = run_on_two_workers(LoadFileScheduling(FakeConfig(reorder=True)), ids(items), seconds)
    assert max(xdist_order) >= max(finish) + 100  # the one-test file last: a worker idles for most of it


def test_update_durations_replaces_what_ran_and_drops_files_that_are_gone(conftest, tmp_path):
    (tmp_path / "tests").mkdir()
    for name in ("test_a.py", "test_b.py"):
        (tmp_path / "tests" / name).write_text("")
    old = {"fast": {"tests/test_a.py": 10, "tests/test_gone.py": 7}, "slow": {"tests/test_a.py": 500}}
    measured = {"fast": {"tests/test_b.py": 12.6}, "slow": {"tests/test_a.py": 321.4}}
    assert conftest.updated_durations(old, measured, tmp_path) == {
        "fast": {"tests/test_a.py": 10, "tests/test_b.py": 13}, "slow": {"tests/test_a.py": 321}}


def test_the_table_holds_only_files_that_exist():
    """A renamed or deleted file's entry would order nothing: ``--update-durations`` drops it."""
    table = json.loads((TESTS / "durations.json").read_text())
    assert set(table) == {"fast", "slow"}
    for tier, files in table.items():
        for file, seconds in files.items():
            assert (TESTS.parent / file).is_file() and seconds >= 0, (tier, file)


def test_compile_time_is_counted_per_test_phase_and_summed_per_file(conftest, monkeypatch):
    """JAX's compile events (and no other event) add up until a phase's report takes them along; the controller
    sums them by file (the terminal summary's "of which compiling" line)."""
    import jax

    monkeypatch.setattr(conftest._Compiling, "seconds", 0.0)
    monkeypatch.setattr(conftest._Compiling, "total", 0.0)
    monkeypatch.setattr(conftest._Compiling, "by_file", {})
    conftest._count_compiling("/jax/core/compile/backend_compile_duration", 1.5)
    conftest._count_compiling("/jax/core/compile/jaxpr_trace_duration", 0.25)
    conftest._count_compiling("/jax/some/other/event", 100.0)
    assert conftest._Compiling.seconds == 1.75
    monkeypatch.setattr(conftest._Compiling, "seconds", 0.0)
    jax.jit(lambda x: x * 3 + 1)(jax.numpy.zeros(7919))  # a shape nothing else compiles: a real compile
    assert conftest._Compiling.seconds > 0.0
    report = SimpleNamespace(duration=2.0, keywords={}, nodeid="tests/test_x.py::t",
                             user_properties=[("compile_s", 1.25)])
    monkeypatch.setattr(conftest._WorkerTime, "total", 0.0)
    monkeypatch.setattr(conftest._WorkerTime, "by_file", {"fast": {}, "slow": {}})
    conftest.pytest_runtest_logreport(report)
    conftest.pytest_runtest_logreport(report)
    assert conftest._Compiling.by_file == {"tests/test_x.py": 2.5} and conftest._Compiling.total == 2.5
