"""Programs found without tracing (issue 39, `cgda_jax.programs.program_scope`):
a config run again finds every program by its key, in memory or in the store on
disk (as a new process would), with the same results; any change of the config,
the model file or a data file is a miss; a damaged store file is compiled again
with a warning."""

import json
import logging
import os
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest

from cgda_jax import model_path
from cgda_jax.experiment import load_config, run_experiment
from cgda_jax.experiment.programs_key import run_programs_key
from cgda_jax.programs import (
    cache_stats,
    clear_programs,
    files_digest,
    program_store,
    set_program_store,
)

# IE on the tiny arm's clean circle, small and short, unconstrained (fewer programs)
TINY = ["kind=execution", "data.source=clean_circle", "scene.kind=marker",
        "strategy.name=ie", "strategy.population_size=8",
        "strategy.max_generations=5", "strategy.tolerance=0.03",
        "strategy.feasibility=false", "robot.substeps=2", "output.render=false",
        "output.plots=false",
        'robot.joints=["yaw", "shoulder", "elbow"]', "robot.fixed={}"]
#: What differs between two runs of one config: the clocks.
TIMES = {"wall_time_s", "compile_time_s", "compute_s", "outputs_s", "total_time_s",
         "folder"}


def _config(model: pathlib.Path, *extra: str):
    return load_config(None, [*TINY, f"robot.model={model}", *extra])


def _run(cfg, folder: pathlib.Path) -> tuple[dict, dict, dict]:
    """The result (clocks aside), its arrays, and what `cache_stats` counted."""
    before = cache_stats()
    run_experiment(cfg, folder)
    after = cache_stats()
    arrays = dict(np.load(folder / "arrays.npz"))
    kept = {k: v for k, v in json.loads((folder / "result.json").read_text()).items()
            if k not in TIMES}
    return kept, arrays, {k: after[k] - before[k] for k in after}


def _same(a, b) -> None:
    assert a[0] == b[0]
    assert a[1].keys() == b[1].keys()
    for k in a[1]:  # NaNs (the padding of the fitness history) equal
        np.testing.assert_array_equal(a[1][k], b[1][k], err_msg=k)


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A model file of its own, a store on disk, and the first run (all traced)."""
    import jax

    if jax.config.jax_compilation_cache_dir:
        # another test in this worker turned JAX's persistent cache on: compiled
        # programs may come from it, and those are not stored (such an executable
        # serializes into one that fails when run; see
        # test_a_program_from_the_persistent_cache_is_not_stored)
        pytest.skip("JAX's persistent compilation cache is on in this process")
    root = tmp_path_factory.mktemp("programs")
    model = root / "arm" / "tiny_arm.xml"
    model.parent.mkdir()
    shutil.copy(model_path("tiny_arm.xml"), model)
    before = program_store()
    set_program_store(root / "store")
    clear_programs()
    try:
        first = _run(_config(model), root / "first")
        yield root, model, (*first, sorted((root / "store").glob("*.prog")),
                            sorted((root / "store").glob("*.key")))
    finally:
        set_program_store(before)


def test_a_config_run_again_traces_nothing_and_finds_the_same(store):
    root, model, first = store
    assert first[2]["traced"] >= 5 and first[2]["keyed_hits"] == 0
    # a link per key asked; a program file per program (two keys may ask for one)
    assert len(first[4]) == first[2]["traced"] and 0 < len(first[3]) <= len(first[4])
    again = _run(_config(model), root / "again")  # in memory
    assert again[2]["traced"] == 0 and again[2]["keyed_hits"] == first[2]["traced"]
    _same(first, again)
    clear_programs()  # as a new process: every program read from the store
    fresh = _run(_config(model), root / "fresh")
    assert fresh[2]["traced"] == 0 and fresh[2]["store_hits"] == first[2]["traced"]
    _same(first, fresh)


def test_another_setting_or_model_is_a_miss(store):
    root, model, first = store
    # a constant of the search, no shape changed: its programs must not be taken
    other = _run(_config(model, "strategy.tolerance=0.05"), root / "tolerance")
    assert other[2]["traced"] >= 4 and other[2]["keyed_hits"] == 0
    changed = root / "changed" / "tiny_arm.xml"
    changed.parent.mkdir()
    changed.write_text(model.read_text().replace("</mujoco>",
                                                 "<!-- edited -->\n</mujoco>"))
    cfg, edited = _config(model), _config(changed)
    assert run_programs_key(cfg, "compute") != run_programs_key(edited, "compute")
    # the same file edited in place: another key
    key = run_programs_key(cfg, "compute")
    text = model.read_text()
    try:
        model.write_text(text + "\n")
        assert run_programs_key(cfg, "compute") != key
    finally:
        model.write_text(text)
    assert run_programs_key(cfg, "compute") == key
    assert run_programs_key(cfg, "check") != key


def test_the_output_settings_are_not_in_the_key(store):
    """Figures, video and folder change no program: a run with its figures on finds
    every program of the same run with them off (the store's first run)."""
    root, model, first = store
    cfg = _config(model)
    for change in ("output.plots=true", "output.render=true", "output.dir=elsewhere",
                   'output.camera={"distance" = 2.0}'):
        assert run_programs_key(_config(model, change), "compute") == \
            run_programs_key(cfg, "compute"), change
    assert run_programs_key(_config(model, "strategy.seed=1"), "compute") != \
        run_programs_key(cfg, "compute")
    drawn = _run(_config(model, "output.plots=true"), root / "drawn")
    assert drawn[2]["traced"] == 0
    assert (root / "drawn" / "plots").is_dir()
    _same(first, (drawn[0] | {"plots": first[0]["plots"]}, drawn[1]))


def test_a_data_file_changed_is_another_key(tmp_path):
    data = tmp_path / "data"
    (data / "sub").mkdir(parents=True)
    (data / "sub" / "demo.csv").write_text("1,2,3\n")
    cfg = load_config(None, ["kind=recognition", "data.source=xgnitive",
                             f"data.data_dir={data}"])
    key = run_programs_key(cfg, "compute")
    assert key == run_programs_key(cfg, "compute")
    (data / "sub" / "demo.csv").write_text("1,2,4\n")
    assert run_programs_key(cfg, "compute") != key
    (data / "sub" / "demo.csv").rename(data / "demo.csv")  # a file moved
    assert files_digest([data]) != files_digest([tmp_path / "none"])
    moved = run_programs_key(cfg, "compute")
    (data / "demo.csv").rename(data / "sub" / "demo.csv")
    assert moved != run_programs_key(cfg, "compute")
    assert files_digest([data], max_bytes=3) is None  # too large to read: no key


def test_a_settled_file_is_read_once_for_the_keys(tmp_path, monkeypatch):
    """A run's two keys (its checks', its search's) read each file once; a file
    changed since, or changed lately (two writes in one tick of the file clock),
    is read again."""
    import hashlib

    reads = []
    digest = hashlib.file_digest
    monkeypatch.setattr(hashlib, "file_digest",
                        lambda f, *a: reads.append(f.name) or digest(f, *a))
    old = tmp_path / "old.xml"
    old.write_text("<a/>")
    past = old.stat().st_mtime_ns - 10**10
    os.utime(old, ns=(past, past))
    first = files_digest([tmp_path])
    assert files_digest([tmp_path]) == first and reads == [str(old)]
    old.write_text("<b/>")  # the same size, a later time
    os.utime(old, ns=(past + 10**9, past + 10**9))
    assert files_digest([tmp_path]) != first and len(reads) == 2
    new = tmp_path / "new.xml"  # just written: read every time
    new.write_text("1")
    files_digest([new])
    files_digest([new])
    assert reads[2:] == [str(new)] * 2


def test_a_damaged_store_file_is_compiled_again_with_a_warning(store, caplog):
    root, model, first = store
    files = sorted(first[3], key=lambda f: f.stat().st_size)[:3]  # quick ones
    files[0].write_bytes(files[0].read_bytes()[:100])  # cut short
    body = bytearray(files[1].read_bytes())
    body[-10] ^= 0xFF  # one byte flipped
    files[1].write_bytes(bytes(body))
    files[2].write_bytes(b"")
    clear_programs()
    with caplog.at_level(logging.WARNING, logger="cgda_jax"):
        again = _run(_config(model), root / "damaged")
    assert again[2]["store_errors"] == 3 and again[2]["traced"] == 3
    assert sum("could not be read" in r.getMessage() for r in caplog.records) == 3
    _same(first, again)
    assert all(f.stat().st_size > 1000 for f in files)  # written again, whole


LAPACK = """
import sys
import jax.numpy as jnp
import numpy as np
from cgda_jax.programs import cache_stats, compile_jit, program_scope, set_program_store
set_program_store(sys.argv[1])
x = jnp.asarray(np.diag([3.0, 1.0, 2.0]).astype(np.float32))
with program_scope(sys.argv[3] if len(sys.argv) > 3 else "a test's key"):  # CMA-ES's eigh: a LAPACK custom call
    w = compile_jit("test.eigh", lambda a: jnp.linalg.eigh(a)[0], x)(x)
s = cache_stats()
print(np.asarray(w).tolist(), s["traced"], s["store_hits"])
"""


def test_a_stored_lapack_program_runs_in_a_new_process(tmp_path):
    """LAPACK's kernels are set up by lowering a call to them, which a program
    read from the store skips: without `_prepare` the second process crashed."""
    out = []
    for _ in range(2):
        proc = subprocess.run([sys.executable, "-c", LAPACK, str(tmp_path)],
                              capture_output=True, text=True, timeout=300,
                              env={**os.environ, "JAX_PLATFORMS": "cpu"})
        assert proc.returncode == 0, proc.stderr[-2000:]
        out.append(proc.stdout.strip().splitlines()[-1])
    assert out == ["[1.0, 2.0, 3.0] 1 0", "[1.0, 2.0, 3.0] 0 1"]


PERSISTENT = """
import sys
import jax
import jax.numpy as jnp
import numpy as np
from cgda_jax.programs import cache_stats, compile_jit, program_scope, set_program_store
jax.config.update("jax_compilation_cache_dir", sys.argv[1])
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
set_program_store(sys.argv[2])
def f(x, y):
    z = jnp.concatenate([x, y * 2.0, jnp.sin(x)])
    return jnp.cumsum(z.reshape(3, -1).T @ z.reshape(3, -1), axis=0).sum()
x, y = jnp.arange(300.0), jnp.ones(300)
with program_scope(sys.argv[3] if len(sys.argv) > 3 else "a test's key"):
    v = compile_jit("test.concat", f, x, y)(x, y)
s = cache_stats()
print(float(v), s["traced"], s["store_hits"])
"""


def test_a_program_from_the_persistent_cache_is_not_stored(tmp_path):
    """On the CPU an executable that JAX's persistent cache served serializes into
    one that fails in a new process ("Function ... not found"): the store keeps
    only programs XLA compiled in the process, and those run when read back."""
    def run(store):
        proc = subprocess.run(
            [sys.executable, "-c", PERSISTENT, str(tmp_path / "jax"), str(store)],
            capture_output=True, text=True, timeout=300,
            env={**os.environ, "JAX_PLATFORMS": "cpu"})
        assert proc.returncode == 0, proc.stderr[-2000:]
        return proc.stdout.strip().splitlines()[-1].split()

    fresh = run(tmp_path / "fresh")  # compiled here: stored
    assert fresh[1:] == ["1", "0"] and len(list((tmp_path / "fresh").glob("*.prog"))) == 1
    served = run(tmp_path / "served")  # the persistent cache's: not stored
    assert served[1:] == ["1", "0"] and not list((tmp_path / "served").glob("*.prog"))
    back = run(tmp_path / "fresh")  # read back from the store, run in a new process
    assert back == [fresh[0], "0", "1"]


def test_another_key_for_a_stored_program_is_linked_to_it(tmp_path):
    """Another key (another seed, the package edited) that traces to a program
    stored before: JAX's persistent cache serves its compile, so nothing new is
    stored, but the key is linked to the stored program and the next process
    finds it without tracing."""
    def run(key):
        proc = subprocess.run(
            [sys.executable, "-c", PERSISTENT, str(tmp_path / "jax"),
             str(tmp_path / "store"), key],
            capture_output=True, text=True, timeout=300,
            env={**os.environ, "JAX_PLATFORMS": "cpu"})
        assert proc.returncode == 0, proc.stderr[-2000:]
        return proc.stdout.strip().splitlines()[-1].split()

    first = run("key 1")  # compiled here: stored, linked
    assert first[1:] == ["1", "0"]
    second = run("key 2")  # traced; the persistent cache's compile: linked
    assert second == [first[0], "1", "0"]
    assert len(list((tmp_path / "store").glob("*.prog"))) == 1
    assert len(list((tmp_path / "store").glob("*.key"))) == 2
    assert run("key 2") == [first[0], "0", "1"]  # found by its link, not traced


def test_cgda_keeps_programs_by_default_and_0_turns_the_store_off(tmp_path, monkeypatch):
    """``cgda`` stores a run's programs in ``$CGDA_JAX_CACHE/programs`` unless
    ``$CGDA_JAX_PROGRAM_STORE=0``."""
    import jax

    from cgda_jax.cli.output import PROGRAM_STORE_ENV, enable_compilation_cache

    flags = ("jax_compilation_cache_dir", "jax_persistent_cache_min_compile_time_secs",
             "jax_persistent_cache_min_entry_size_bytes")
    saved = {k: getattr(jax.config, k) for k in flags}
    before = program_store()
    try:
        monkeypatch.delenv(PROGRAM_STORE_ENV, raising=False)
        path = enable_compilation_cache(tmp_path / "cache")
        assert program_store() == path / "programs"
        monkeypatch.setenv(PROGRAM_STORE_ENV, "0")
        enable_compilation_cache(tmp_path / "cache")
        assert program_store() is None
    finally:  # the rest of this process as it was
        for k, v in saved.items():
            jax.config.update(k, v)
        set_program_store(before)


def test_a_program_compiled_ahead_is_the_one_asked_for():
    """`compile_ahead` compiles in another thread the program the next
    `compile_jit` of the same place and types asks for, under the same key."""
    import threading

    import jax
    import jax.numpy as jnp

    from cgda_jax.programs import compile_ahead, compile_jit, program_scope

    traced_in = []

    def f(x):
        traced_in.append(threading.current_thread().name)
        return jnp.cumsum(x) * 2.0

    x = jax.ShapeDtypeStruct((5,), jnp.float32)
    before = cache_stats()
    with program_scope("a test of compile_ahead"):
        compile_ahead("test.ahead", f, x)
        first = compile_jit("test.ahead", f, x)  # waits for the thread's
        second = compile_jit("test.ahead", f, x)  # the next one: not the same
    assert traced_in[0] == "cgda-compile-test.ahead"  # (JAX traces f once)
    assert cache_stats()["traced"] - before["traced"] == 2
    np.testing.assert_array_equal(first(jnp.arange(5.0)), [0, 2, 6, 12, 20])
    again = cache_stats()
    with program_scope("a test of compile_ahead"):  # as keyed without ahead
        assert compile_jit("test.ahead", f, x) is first
        assert compile_jit("test.ahead", f, x) is second
    assert cache_stats()["keyed_hits"] - again["keyed_hits"] == 2


def test_programs_asked_ahead_are_traced_one_at_a_time_by_rank():
    """`compile_ahead`'s threads trace one at a time, the lowest rank first (the
    critical program's trace is not slowed by the others'), a deferred program
    only once another is asked, and one never asked so is compiled by its user."""
    import threading
    import time

    import jax
    import jax.numpy as jnp

    from cgda_jax.programs import compile_ahead, compile_jit, program_scope

    order, inside, overlaps = [], [0], []

    def traced(label, scale, slow=0.0):
        def f(x):
            inside[0] += 1
            overlaps.append(inside[0])
            order.append((label, threading.current_thread().name))
            time.sleep(slow)  # a long trace: the others are asked meanwhile
            inside[0] -= 1
            return x * scale
        return f

    x = jax.ShapeDtypeStruct((3,), jnp.float32)
    first, low, last = traced("first", 2.0, 0.5), traced("low", 3.0), traced("last", 4.0)
    with program_scope("a test of tracing turns"):
        compile_ahead("test.last", last, x, rank=2, defer=True)
        assert order == []  # deferred: not asked yet
        compile_ahead("test.first", first, x, rank=0)  # asks the deferred one too
        compile_ahead("test.low", low, x, rank=1)  # asked after it, traced before it
        got = [compile_jit(n, f, x) for n, f in (("test.first", first),
                                                 ("test.low", low),
                                                 ("test.last", last))]
    assert [label for label, _ in order] == ["first", "low", "last"]
    assert all(t.startswith("cgda-compile-") for _, t in order)
    assert max(overlaps) == 1  # never two traces at once
    for prog, scale in zip(got, (2.0, 3.0, 4.0)):
        np.testing.assert_array_equal(prog(jnp.ones(3)), [scale] * 3)
    order.clear()
    never = traced("never", 5.0)
    with program_scope("a test of tracing turns, never asked"):
        compile_ahead("test.never", never, x, rank=2, defer=True)
        prog = compile_jit("test.never", never, x)
    assert order == [("never", threading.current_thread().name)]
    np.testing.assert_array_equal(prog(jnp.ones(3)), [5.0] * 3)


def test_a_program_asked_inside_a_trace_in_its_turn_does_not_wait():
    """A function traced in its turn that asks for a program asked ahead behind it
    gets it compiled in its own thread instead of waiting for a turn that comes
    only after its own trace ends."""
    import concurrent.futures

    import jax
    import jax.numpy as jnp

    from cgda_jax.programs import compile_ahead, compile_jit, program_scope

    x = jax.ShapeDtypeStruct((3,), jnp.float32)

    def inner(y):
        return y + 1.0

    def outer(y):
        prog = compile_jit("test.inner", inner, x)  # asked ahead, behind this trace
        assert prog is not None
        return y * 2.0

    def run():
        with program_scope("a test of a program asked inside a trace"):
            compile_ahead("test.inner", inner, x, rank=2, defer=True)
            compile_ahead("test.outer", outer, x, rank=0)  # asks inner behind it
            return compile_jit("test.outer", outer, x)

    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        prog = pool.submit(run).result(timeout=120)  # a deadlock fails here
    np.testing.assert_array_equal(prog(jnp.ones(3)), [2.0] * 3)


def test_a_job_s_processes_keep_their_programs_apart(monkeypatch):
    """An executable runs on the devices it was compiled for: in a cluster job,
    process 1 must not find under a run's key the program process 0 stored
    (it failed with "local device count is 0")."""
    import jax

    from cgda_jax.programs import environment_digest

    here = environment_digest()
    assert environment_digest() == here
    monkeypatch.setattr(jax, "process_index", lambda: 1)
    assert environment_digest() != here
