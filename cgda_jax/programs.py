"""Compiled programs reused within a process and across processes.

A run builds its plan, its simulator and its checks anew, as closures over new
objects; ``jax.jit`` keys its cache on the Python function, so the same
experiment run again would trace, lower and compile every program again.  Two
ways to find a program compiled before:

By what determines it, before tracing (`program_scope`, `compile_jit`): inside a
scope whose key names everything a run's programs depend on (the experiment's
resolved config, the content of every file it reads, the package's source, the
versions of jax, jaxlib, MuJoCo, evosax and optax, the backend and its devices,
JAX's numerics flags: `environment_digest`, `files_digest`, and
`cgda_jax.experiment.programs_key.run_programs_key`), a program is keyed by the
scope's key, the name of the place that builds it, its arguments' types and
shardings, its ``jax.jit`` options and how many programs of that place and types the
scope asked for before it (a run is deterministic: the same inputs ask for the
same programs in the same order; `compile_ahead` starts one in a thread, to
be taken by the call that asks for it).  Found in memory or in the store on disk
(`set_program_store`; ``cgda`` keeps it in its compilation cache folder unless
``$CGDA_JAX_PROGRAM_STORE=0``), it is
used without tracing; any change of config, data, model or code gives another
key, hence a miss (traced, compiled, kept).  A stored program is the executable
XLA compiled in the process (one JAX's persistent cache served is not stored: on
the CPU it serializes into a program that fails in a new process), by
``jax.experimental.serialize_executable``, written atomically in a
versioned file named by what it computes (the key below) with a checksum; each
key that asked for it is a small link file naming that program.  A key that
misses but traces to a program stored before under another key (another seed,
the package edited elsewhere: JAX's persistent cache serves the compile, so it is
not stored again) is linked to it, and found without tracing from then on (a
program JAX's persistent cache holds that the store never had, compiled outside
a scope or dropped by its bound, is traced on every run: a new
``$CGDA_JAX_CACHE`` folder starts both afresh).  A file that cannot be read back
(cut short, corrupt, another version) is dropped with a warning and the program
compiled again.  The store is bounded
(`MAX_STORE_BYTES` of programs, `MAX_LINKS` links; least recently used dropped).

By what it computes (`compile_lowered`): outside a scope, a program is keyed by
its lowered StableHLO text (constants included, no source locations), its
argument and result trees, every argument's type (an unused argument is pruned
from the text but still checked by the call) and the backend and devices, the
same content JAX's persistent cache keys on.  Tracing and lowering still run,
compiling does not.

Programs that call back into Python (``jax.pure_callback``: the MuJoCo C physics
backend) are never shared either way: their text names the callback by an index,
not by what it calls.  At most `MAX_PROGRAMS` of each kind are kept in memory
(least recently used dropped).  The source digest is taken once per process, on
first use: edit the package while a process runs and that process keeps its
digest; code replaced in a running process (a test's monkeypatch of a function a
program calls) is not seen by the key either: run such code outside a scope.
"""

from __future__ import annotations

import collections
import concurrent.futures
import contextlib
import contextvars
import functools
import hashlib
import logging
import os
import pathlib
import pickle
import re
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import jax

__all__ = ["MAX_LINKS", "MAX_PROGRAMS", "MAX_STORE_BYTES", "RUN_ONCE_OPTIONS",
           "STORE_VERSION",
           "cache_stats",
           "clear_programs", "compile_ahead", "compile_jit", "compile_lowered",
           "environment_digest", "files_digest", "jit_call", "program_scope", "program_store",
           "set_program_store"]

log = logging.getLogger("cgda_jax")

#: ``jax.jit``'s ``compiler_options`` for a program that runs once and whose
#: values are only compared with a threshold (`cgda_jax.sim.feasibility.relevant_pairs`'
#: start distances): LLVM unoptimized, about 40 % less XLA compile time; the values
#: may differ from the optimized program's in the last bits (float32 round-off).
RUN_ONCE_OPTIONS = {"xla_backend_optimization_level": 0}
#: Compiled programs kept in memory at most (each way of finding them).
MAX_PROGRAMS = 64
#: Bytes the program store on disk holds at most (oldest files dropped past it).
MAX_STORE_BYTES = 512 * 2**20
#: Key links the store holds at most (64 bytes each; least recently used dropped).
MAX_LINKS = 20_000
#: The store's file format; another version's files are misses.
STORE_VERSION = 2
_MAGIC = b"cgda-program"

_PROGRAMS: collections.OrderedDict[str, Any] = collections.OrderedDict()
_KEYED: collections.OrderedDict[str, Any] = collections.OrderedDict()
_STATS = {"hits": 0, "misses": 0, "uncached": 0, "keyed_hits": 0, "store_hits": 0,
          "traced": 0, "store_errors": 0}
_LOCK = threading.Lock()
_STORE: list[pathlib.Path | None] = [None]


def _key(lowered: jax.stages.Lowered, text: str) -> str | None:
    """The program's key, or None for one that must not be shared."""
    if "callback" in text:  # host callbacks: named by index, not by what they do
        return None
    # an executable runs on the devices it was compiled for: this process's (a
    # program of process 0 of a job fails in process 1, whose device is another)
    devices = [(d.platform, d.id) for d in jax.devices()], _local_devices()
    # every argument's type: an unused one is left out of the text, not the call
    args = [(a.shape, str(a.dtype), a.donated)
            for a in jax.tree.leaves(lowered.args_info)]
    h = hashlib.sha256(text.encode())
    h.update(repr((str(lowered.in_tree), str(lowered.out_tree), args, devices,
                   jax.default_backend())).encode())
    return h.hexdigest()


def _remember(store: collections.OrderedDict, key: str, compiled: Any) -> None:
    with _LOCK:
        store[key] = compiled
        store.move_to_end(key)
        while len(store) > MAX_PROGRAMS:
            store.popitem(last=False)


def compile_lowered(lowered: jax.stages.Lowered) -> jax.stages.Compiled:
    """``lowered.compile()``, or the program compiled before in this process from
    the same lowered text (see the module doc).

    Args:
        lowered: ``jax.jit(f, ...).lower(*args)``.
    """
    return _compile(lowered, lowered.as_text())[0]


#: Per thread: how many programs JAX's persistent cache has served it.
_PERSISTENT = threading.local()
_LISTENING: list[bool] = [False]


def _count_persistent_hit(event: str, **_: Any) -> None:
    if event == "/jax/compilation_cache/cache_hits":
        _PERSISTENT.hits = getattr(_PERSISTENT, "hits", 0) + 1


def _xla_compile(lowered: jax.stages.Lowered) -> tuple[jax.stages.Compiled, bool]:
    """``lowered.compile()``, and whether XLA compiled it here (False: JAX's
    persistent cache served it; on the CPU such an executable, serialized, fails
    when run in a new process, so the store keeps only fresh ones)."""
    with _LOCK:
        if not _LISTENING[0]:
            jax.monitoring.register_event_listener(_count_persistent_hit)
            _LISTENING[0] = True
    before = getattr(_PERSISTENT, "hits", 0)
    compiled = lowered.compile()
    return compiled, getattr(_PERSISTENT, "hits", 0) == before


def _compile(lowered: jax.stages.Lowered, text: str
             ) -> tuple[jax.stages.Compiled, str | None, bool]:
    """`compile_lowered` of ``lowered`` (its text ``text``), the program's key by
    what it computes (`_key`; None: not to be shared), and whether XLA compiled
    it in this process (`_xla_compile`)."""
    key = _key(lowered, text)
    if key is None:
        with _LOCK:
            _STATS["uncached"] += 1
        return lowered.compile(), None, False
    with _LOCK:
        found = _PROGRAMS.get(key)
        if found is not None:
            _PROGRAMS.move_to_end(key)
            _STATS["hits"] += 1
            return found[0], key, found[1]
    compiled, fresh = _xla_compile(lowered)
    with _LOCK:
        _STATS["misses"] += 1
    _remember(_PROGRAMS, key, (compiled, fresh))
    return compiled, key, fresh


# ------------------------------------------------------------- keyed before tracing
class _Scope:
    def __init__(self, key: str):
        self.key = key
        self.asked: collections.Counter[str] = collections.Counter()
        # `compile_ahead`: the programs compiling in a thread (by key) and how
        # many of each kind were asked ahead and not taken yet
        self.ahead: dict[str, concurrent.futures.Future] = {}
        self.reserved: collections.Counter[str] = collections.Counter()
        # `compile_ahead(defer=True)`: (what, name, fn, args, rank, jit_kw) not asked yet
        self.deferred: list[tuple] = []


_SCOPE: contextvars.ContextVar[_Scope | None] = contextvars.ContextVar(
    "cgda_program_scope", default=None)


@contextlib.contextmanager
def program_scope(key: str | None) -> Iterator[None]:
    """Inside, `compile_jit` finds the programs compiled before under ``key`` (in
    this process or in the store) without tracing them.

    Args:
        key: a digest of everything the programs compiled inside depend on besides
            their arguments' types (`environment_digest`, `files_digest`, the
            config); None: no reuse by key (`compile_lowered` still applies).
    """
    token = _SCOPE.set(None if key is None else _Scope(key))
    try:
        yield
    finally:
        _SCOPE.reset(token)


def _leaf_type(x: Any) -> tuple:
    sharding = getattr(x, "sharding", None)
    return (type(x).__name__, tuple(getattr(x, "shape", ())),
            str(getattr(x, "dtype", type(x).__name__)), getattr(x, "weak_type", None),
            repr(sharding) if sharding is not None else None)


def _what(name: str, args: tuple, jit_kw: dict) -> str:
    """What a program of the place ``name`` is asked for: its arguments' tree and
    types, its ``jax.jit`` options."""
    leaves, tree = jax.tree.flatten(args)
    return repr((name, str(tree), [_leaf_type(x) for x in leaves],
                 sorted((k, repr(v)) for k, v in jit_kw.items())))


def _program_key(scope: _Scope, what: str, n: int) -> str:
    return hashlib.sha256(f"{scope.key}\n{what}\n{n}".encode()).hexdigest()


def compile_jit(name: str, fn: Callable, *args: Any, **jit_kw: Any
                ) -> jax.stages.Compiled:
    """``jax.jit(fn, **jit_kw).lower(*args).compile()``: inside a `program_scope`
    found by key without tracing when compiled before (in memory or in the store)
    or asked for ahead (`compile_ahead`), else traced and compiled through
    `compile_lowered` and kept under its key.

    Args:
        name: the place that builds ``fn`` (one name per place: a module and what
            it compiles).
        fn, args: the function and its arguments (arrays or
            ``jax.ShapeDtypeStruct``).
        jit_kw: ``jax.jit`` options (shardings).
    """
    scope = _SCOPE.get()
    if scope is None:
        return _find_or_compile(None, fn, args, jit_kw)
    what = _what(name, args, jit_kw)
    with _LOCK:
        # a deferred ask not made yet: this call compiles it
        scope.deferred = [d for d in scope.deferred if d[0] != what]
        key = _program_key(scope, what, scope.asked[what])
        scope.asked[what] += 1
        pending = scope.ahead.pop(key, None)
        if pending is not None:
            scope.reserved[what] -= 1
    if pending is not None and _TracingTurns.held_here():
        # asked inside a trace in its turn: the thread asked ahead would wait for
        # this trace to end; compiled here instead (its thread compiles it too)
        pending = None
    if pending is not None:
        try:
            return pending.result()
        except Exception as err:  # noqa: BLE001 - compiled here instead, raising here
            log.debug("program %s compiled ahead failed (%s); compiling it here",
                      name, err)
    return _find_or_compile(key, fn, args, jit_kw)


def compile_ahead(name: str, fn: Callable, *args: Any, rank: int = 1,
                  defer: bool = False, **jit_kw: Any) -> None:
    """Start finding or compiling, in a thread, the program that the next
    `compile_jit` of ``name`` with these argument types in this `program_scope`
    asks for (it then waits for it): a program the run needs later compiles
    while the run computes (XLA compiles without Python's lock, on another
    core). Outside a scope, nothing. A program asked ahead and never asked for is
    compiled for nothing: ask only for what the run will use. Where JAX's
    settings differ in the thread (a ``with jax.default_matmul_precision(...)``
    holds in its own thread only), the caller compiles it instead.

    Args:
        name: as `compile_jit`'s.
        fn: as `compile_jit`'s.
        args: ``jax.ShapeDtypeStruct`` or arrays: the same types the call passes.
        rank: which traces first: programs asked ahead are traced one at a time
            (tracing holds Python's lock: side by side they would all finish
            late), the lowest rank first, then in the order asked; each
            compiles (XLA, without the lock) as soon as it is traced. Give the
            program on the run's critical path (the longest to compile) rank 0.
        defer: ask it only with the scope's next program asked ahead without
            ``defer`` (behind it, by ``rank``): a program the run needs last
            (the result's checks) then takes no tracing time from the programs
            the run builds meanwhile. Never asked so, it is compiled when used.
        jit_kw: as `compile_jit`'s.
    """
    scope = _SCOPE.get()
    if scope is None:
        return
    what = _what(name, args, jit_kw)
    if defer:
        with _LOCK:
            scope.deferred.append((what, name, fn, args, rank, jit_kw))
        return
    _ask_ahead(scope, what, name, fn, args, rank, jit_kw)
    with _LOCK:
        deferred, scope.deferred = scope.deferred, []
    for d_what, d_name, d_fn, d_args, d_rank, d_kw in deferred:
        _ask_ahead(scope, d_what, d_name, d_fn, d_args, d_rank, d_kw)


def _ask_ahead(scope: _Scope, what: str, name: str, fn: Callable, args: tuple,
               rank: int, jit_kw: dict) -> None:
    """`compile_ahead` of one program, asked now."""
    with _LOCK:
        key = _program_key(scope, what, scope.asked[what] + scope.reserved[what])
        scope.reserved[what] += 1
        future: concurrent.futures.Future = concurrent.futures.Future()
        scope.ahead[key] = future

    numerics = _numerics()
    turn = _TracingTurns.ticket(rank)

    def work() -> None:
        try:
            if _numerics() != numerics:  # a thread-local setting: not here
                raise RuntimeError("JAX's settings differ in the compiling thread")
            future.set_result(_find_or_compile(key, fn, args, jit_kw, turn))
        except BaseException as err:  # noqa: BLE001 - raised to the caller
            future.set_exception(err)
        finally:
            _TracingTurns.drop(turn)

    context = contextvars.copy_context()
    threading.Thread(target=context.run, args=(work,), daemon=True,
                     name=f"cgda-compile-{name}").start()


class _TracingTurns:
    """The order in which `compile_ahead`'s threads trace: one at a time, the
    lowest ``(rank, ticket)`` waiting first (`compile_ahead`)."""

    _cond = threading.Condition()
    _waiting: list[tuple[int, int]] = []
    _busy: list[int | None] = [None]  # the tracing thread's ident
    _count = [0]

    @classmethod
    def held_here(cls) -> bool:
        """Whether this thread is tracing in its turn (a program it asks for
        inside its trace must not wait for a turn behind its own)."""
        return cls._busy[0] == threading.get_ident()

    @classmethod
    def ticket(cls, rank: int) -> tuple[int, int]:
        """A place in the order, taken when the program is asked ahead."""
        with cls._cond:
            cls._count[0] += 1
            t = (int(rank), cls._count[0])
            cls._waiting.append(t)
            return t

    @classmethod
    @contextlib.contextmanager
    def turn(cls, t: tuple[int, int]) -> Iterator[None]:
        """Wait until ``t`` is the first waiting and nobody traces; trace inside."""
        with cls._cond:
            cls._cond.wait_for(lambda: cls._busy[0] is None
                               and min(cls._waiting) == t)
            cls._waiting.remove(t)
            cls._busy[0] = threading.get_ident()
        try:
            yield
        finally:
            with cls._cond:
                cls._busy[0] = None
                cls._cond.notify_all()

    @classmethod
    def drop(cls, t: tuple[int, int]) -> None:
        """Give up ``t`` if still waiting (its program found compiled, or failed)."""
        with cls._cond:
            if t in cls._waiting:
                cls._waiting.remove(t)
                cls._cond.notify_all()


def _find_or_compile(key: str | None, fn: Callable, args: tuple, jit_kw: dict,
                     turn: tuple[int, int] | None = None) -> jax.stages.Compiled:
    """The program of ``key`` from memory or the store, else traced (in its
    `_TracingTurns` ``turn`` when given), compiled and kept (None: `compile_lowered`
    only)."""
    if key is not None:
        with _LOCK:
            found = _KEYED.get(key)
            if found is not None:
                _KEYED.move_to_end(key)
                _STATS["keyed_hits"] += 1
                return found
        found = _load(key)
        if found is not None:
            _remember(_KEYED, key, found)
            return found
    with contextlib.nullcontext() if turn is None else _TracingTurns.turn(turn):
        lowered = jax.jit(fn, **jit_kw).lower(*args)
        text = lowered.as_text()
    with _LOCK:
        _STATS["traced"] += 1
    compiled, content, fresh = _compile(lowered, text)
    if key is not None and content is not None:
        _remember(_KEYED, key, compiled)
        # stored once by what it computes; ``key`` linked to it (also when JAX's
        # persistent cache served this compile and another key stored it fresh)
        if (fresh and _save(content, compiled, set(_CUSTOM_CALL.findall(text)))
                or _stored(content)):
            _link(key, content)
    return compiled


def jit_call(fn: Callable, *args: Any, name: str | None = None, **jit_kw: Any) -> Any:
    """``jax.jit(fn, **jit_kw)(*args)`` through `compile_jit` (named after ``fn``
    unless ``name``): for a function built anew on each call (a closure over a new
    simulator) whose program is often the same."""
    name = name or f"{getattr(fn, '__module__', '')}.{getattr(fn, '__qualname__', fn)}"
    return compile_jit(name, fn, *args, **jit_kw)(*args)


# -------------------------------------------------------------------------- store
def set_program_store(folder: str | os.PathLike | None) -> None:
    """Keep the programs compiled in a `program_scope` in ``folder`` too (None: in
    memory only)."""
    _STORE[0] = None if folder is None else pathlib.Path(folder)


def program_store() -> pathlib.Path | None:
    """The folder `set_program_store` set, or None."""
    return _STORE[0]


#: A custom call in a program's text: its target's name.
_CUSTOM_CALL = re.compile(r"custom_call @([\w.$-]+)")


def _storable(targets: set[str]) -> bool:
    """A program whose custom calls are all LAPACK's (CMA-ES's ``eigh``: its
    handlers are set up before loading, `_prepare`) or none; another custom call's
    handler may need a set-up that lowering does and loading does not, so such a
    program is kept in memory only."""
    return all(t.startswith("lapack_") for t in targets)


def _prepare(targets: Iterable[str]) -> None:
    """Set up what a loaded program's custom calls need (LAPACK's kernels are set
    up by lowering a LAPACK call, which a loaded program skips: without it the
    call crashes the process)."""
    if any(t.startswith("lapack_") for t in targets):
        import numpy as np
        from jaxlib import lapack

        lapack.prepare_lapack_call("syevd", np.float32)


def _path(content: str, kind: str = "prog") -> pathlib.Path | None:
    """A program's file (``kind`` "prog", named by `_key`) or a key's link
    ("key", named by the `program_scope` key)."""
    folder = _STORE[0]
    return None if folder is None else folder / f"{content}.v{STORE_VERSION}.{kind}"


def _stored(content: str) -> bool:
    path = _path(content)
    return path is not None and path.is_file()


def _link(key: str, content: str) -> None:
    """Write that ``key`` asks for the stored program ``content``."""
    path = _path(key, "key")
    if path is None:
        return
    try:
        _write(path, content.encode())
    except OSError as err:
        log.warning("program store %s not written: %s", path.parent, err)


def _load(key: str) -> jax.stages.Compiled | None:
    """The program a key's link names, read from the store (None: no link, or
    its program was dropped)."""
    link = _path(key, "key")
    if link is None or not link.is_file():
        return None
    try:
        content = link.read_text().strip()
    except (OSError, UnicodeDecodeError):
        content = ""
    path = _path(content) if re.fullmatch(r"[0-9a-f]{64}", content) else None
    if path is None or not path.is_file():
        return None  # a link whose program was dropped (`_bound`): a miss
    with _LOCK:  # read for another key in this process already
        found = _PROGRAMS.get(content)
        if found is not None:
            _PROGRAMS.move_to_end(content)
            _STATS["store_hits"] += 1
            return found[0]
    from jax.experimental import serialize_executable

    try:
        data = path.read_bytes()
        head = _MAGIC + f" {STORE_VERSION} {content}\n".encode()
        digest, body = data[len(head):len(head) + 32], data[len(head) + 32:]
        if not data.startswith(head) or hashlib.sha256(body).digest() != digest:
            raise ValueError("not a complete program file of this version")
        payload, in_tree, out_tree, targets = pickle.loads(body)
        if not _storable(targets):
            raise ValueError(f"custom calls {sorted(targets)} cannot be loaded")
        _prepare(targets)
        compiled = serialize_executable.deserialize_and_load(payload, in_tree, out_tree)
    except Exception as err:  # noqa: BLE001 - any unreadable file is a miss
        with _LOCK:
            _STATS["store_errors"] += 1
        log.warning("stored program %s could not be read (%s: %s); compiling it "
                    "again", path, type(err).__name__, err)
        with contextlib.suppress(OSError):
            path.unlink()
        return None
    with _LOCK:
        _STATS["store_hits"] += 1
    _remember(_PROGRAMS, content, (compiled, False))
    for used in (path, link):  # recently used: dropped last
        with contextlib.suppress(OSError):
            os.utime(used)
    return compiled


def _save(content: str, compiled: jax.stages.Compiled, targets: set[str]) -> bool:
    """Store a program XLA compiled here under its `_key`; whether it is stored."""
    path = _path(content)
    if path is None or not _storable(targets):
        return False
    from jax.experimental import serialize_executable

    try:
        body = pickle.dumps((*serialize_executable.serialize(compiled), targets),
                            protocol=pickle.HIGHEST_PROTOCOL)
    except Exception as err:  # noqa: BLE001 - a program that cannot be stored
        log.debug("program %s not stored: %s", content, err)
        return False
    try:
        _write(path, _MAGIC + f" {STORE_VERSION} {content}\n".encode()
               + hashlib.sha256(body).digest() + body)
        _bound(path.parent, "prog", max_bytes=MAX_STORE_BYTES)
        _bound(path.parent, "key", max_files=MAX_LINKS)
    except OSError as err:
        log.warning("program store %s not written: %s", path.parent, err)
        return False
    return True


def _write(path: pathlib.Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (a reader sees all of it or none)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except OSError:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _bound(folder: pathlib.Path, kind: str, *, max_bytes: int | None = None,
           max_files: int | None = None) -> None:
    """Drop the least recently used files of ``kind`` past ``max_bytes`` or
    ``max_files``."""
    files = []
    for p in folder.glob(f"*.{kind}"):
        with contextlib.suppress(OSError):
            st = p.stat()
            files.append((st.st_mtime, st.st_size, p))
    total, count = sum(f[1] for f in files), len(files)
    for _, size, p in sorted(files, key=lambda f: f[0]):
        if ((max_bytes is None or total <= max_bytes)
                and (max_files is None or count <= max_files)):
            break
        with contextlib.suppress(OSError):
            p.unlink()
            total -= size
            count -= 1


# ------------------------------------------------------------------------ digests
def files_digest(paths: Iterable[str | os.PathLike], max_bytes: int = 256 << 20,
                 max_files: int = 5000) -> str | None:
    """SHA-256 over the names and contents of ``paths`` (a folder: every file
    under it, sorted); None when they hold more than ``max_bytes`` or
    ``max_files`` (too much to read for a key: no reuse by key)."""
    h = hashlib.sha256()
    total = 0
    count = 0
    for root in sorted({pathlib.Path(p).resolve() for p in paths}):
        files = []
        if root.is_dir():
            for q in root.rglob("*"):
                count += 1
                if count > max_files:
                    return None
                if q.is_file():
                    files.append(q)
            files.sort()
        elif root.is_file():
            files = [root]
        h.update(f"{root}:{len(files)}\n".encode())
        for f in files:
            st = f.stat()
            total += st.st_size
            if total > max_bytes:
                return None
            h.update(f"{f.relative_to(root) if root.is_dir() else f.name}\n".encode())
            h.update(_file_digest(f, st))
    return h.hexdigest()


#: A file's content digest by its path and what ``stat`` says of it (inode, size,
#: modification time in ns): a run's keys (its checks', its search's) read each of
#: its files once.
_FILE_DIGESTS: dict[tuple, bytes] = {}
#: A file modified less than this long ago (ns) is read every time: the clock that
#: stamps files ticks coarsely, so two writes of one size in a tick look the same.
_SETTLED_NS = 2_000_000_000


def _file_digest(path: pathlib.Path, st: os.stat_result) -> bytes:
    """SHA-256 of ``path``'s content (``st`` its stat), read again only when the
    file changed (another inode, size or modification time) or changed lately
    (`_SETTLED_NS`)."""
    seen = (str(path), st.st_ino, st.st_size, st.st_mtime_ns)
    with _LOCK:
        found = _FILE_DIGESTS.get(seen)
    if found is not None:
        return found
    with open(path, "rb") as fh:
        digest = hashlib.file_digest(fh, "sha256").digest()
    if time.time_ns() - st.st_mtime_ns < _SETTLED_NS:
        return digest
    with _LOCK:
        if len(_FILE_DIGESTS) > 100_000:  # bounded: a process reading many trees
            _FILE_DIGESTS.clear()
        _FILE_DIGESTS[seen] = digest
    return digest


@functools.cache
def _source_digest() -> str:
    package = pathlib.Path(__file__).resolve().parent
    return files_digest(sorted(package.rglob("*.py"))) or ""


@functools.cache
def _version(dist: str) -> str:
    from importlib import metadata

    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "-"


@functools.cache
def _host() -> str:
    """The machine and, on Linux, the CPU's model and instruction-set flags (XLA
    compiles CPU programs for the host's: a store shared by two machines must not
    give one the other's)."""
    import platform

    lines = []
    with contextlib.suppress(OSError):
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.startswith(("model name", "flags", "Features")):
                    lines.append(line.strip())
                if len(lines) >= 2:
                    break
    return repr((platform.machine(), platform.processor(), lines))


#: JAX's settings that change what a program computes.
_NUMERICS_FLAGS = ("jax_enable_x64", "jax_default_matmul_precision",
                   "jax_numpy_rank_promotion", "jax_default_prng_impl",
                   "jax_threefry_partitionable", "jax_disable_jit")


def _numerics() -> dict[str, Any]:
    """`_NUMERICS_FLAGS` as this thread sees them (a ``with`` of JAX's holds in
    its own thread only)."""
    return {k: getattr(jax.config, k, None) for k in _NUMERICS_FLAGS}


def environment_digest() -> str:
    """SHA-256 of what a program depends on besides its experiment: the package's
    source (every ``cgda_jax/**/*.py``), the versions of Python, jax, jaxlib,
    MuJoCo (and MJX), evosax, optax and NumPy, the backend and its devices (this
    process's among them: a job's processes keep programs apart), the host's CPU
    (model, instruction sets), JAX's numerics flags and
    ``$XLA_FLAGS``."""
    flags = _numerics()
    what = repr((_source_digest(), _host(), sys.version,
                 [_version(d) for d in ("jax", "jaxlib", "mujoco", "mujoco-mjx",
                                        "evosax", "optax", "numpy")],
                 jax.default_backend(),
                 [(d.platform, d.device_kind, d.id) for d in jax.devices()],
                 _local_devices(),
                 sorted(flags.items()), os.environ.get("XLA_FLAGS", "")))
    return hashlib.sha256(what.encode()).hexdigest()


def _local_devices() -> tuple:
    """This process's index and devices: a compiled program is bound to them."""
    return jax.process_index(), [(d.platform, d.id) for d in jax.local_devices()]


def cache_stats() -> dict[str, int]:
    """Since the process started (or `clear_programs`): `compile_lowered`'s
    ``hits``, ``misses`` (compiled and kept) and ``uncached`` (host callbacks);
    `compile_jit`'s ``keyed_hits`` (in memory), ``store_hits`` (read from the
    store), ``store_errors`` (files dropped) and ``traced`` (programs traced and
    lowered); ``programs`` and ``keyed`` kept now."""
    with _LOCK:
        return dict(_STATS, programs=len(_PROGRAMS), keyed=len(_KEYED))


def clear_programs() -> None:
    """Forget every program kept in memory and zero `cache_stats` (the store on
    disk stays)."""
    with _LOCK:
        _PROGRAMS.clear()
        _KEYED.clear()
        for k in _STATS:
            _STATS[k] = 0
