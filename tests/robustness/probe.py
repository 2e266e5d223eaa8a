"""Run the hostile-input corpus (hostile_corpus.py) through the real `darthand` CLI; print what was handled, by class.

    .venv/bin/python tests/robustness/probe.py [--work DIR] [--jobs N] [--only TEXT] [--json OUT] [--no-make]
                                               [--source CHECKOUT]

--source runs another checkout's code (e.g. `git archive main | tar -x -C /tmp/main-src`, with .venv and
node_modules linked into it) through this .venv, for a before/after comparison.

Each case runs in a subprocess of its own session, in its own folder, under an address-space limit (8 GiB, so that
a runaway allocation fails instead of swapping the machine), with a timeout. It is judged, first failure wins:

    hang          the command did not finish within the case's timeout
    crash         it died of a signal (segmentation fault, abort, out-of-memory kill)
    read outside  it opened a file outside the package (inotify watch on the outside files)
    payload ran   a malicious pickle's payload created its marker file
    traceback     a Python traceback on stderr
    exit N        an exit code other than the case's expected ones (0: the bad input was accepted)
    no message    exit 2 without a one-line `darthand: error:` message
    orphans       processes of its session still alive after it exited
    noise         warnings on stderr (leaked semaphores, 'Exception ignored')
    check         the case's own check of what was left behind failed

The interruption and damage cases (Ctrl-C during a run, SIGKILL and re-run, `make assets` interrupted, a damaged
build output) run several commands each and are judged the same way.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import ctypes
import errno
import json
import os
import re
import resource
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter, defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
sys.path[:0] = [str(HERE), str(HERE.parent), str(HERE.parent / "model")]


from hostile_corpus import CASES, Case, case, text  # noqa: E402
from probe_fixtures import build_fixtures  # noqa: E402

DARTHAND = str(Path(sys.executable).parent / "darthand")
MEMORY_LIMIT = 8 << 30
SOURCE = REPO                  # the checkout whose code runs (--source)


@dataclass
class Result:
    id: str
    klass: str
    name: str
    verdict: str                 # 'handled' or the failure kind
    exit: int | None = None
    seconds: float = 0.0
    detail: str = ""
    argv: list = field(default_factory=list)


# ------------------------------------------------------------------------------------------------ watching files

_libc = ctypes.CDLL("libc.so.6", use_errno=True)
IN_OPEN, IN_ACCESS = 0x20, 0x01


class Watch:
    """inotify IN_OPEN/IN_ACCESS on some files: did anything open them?"""

    def __init__(self, paths):
        self.fd = -1
        for _ in range(40):     # EMFILE: every process of the user shares fs.inotify.max_user_instances (128)
            self.fd = _libc.inotify_init1(os.O_NONBLOCK | os.O_CLOEXEC)
            if self.fd >= 0 or ctypes.get_errno() != errno.EMFILE:
                break
            time.sleep(0.25)
        if self.fd < 0:
            raise OSError(ctypes.get_errno(), f"inotify_init1: {os.strerror(ctypes.get_errno())}")
        self.names = {}
        for p in paths:
            if os.path.lexists(p) and not Path(p).is_fifo():
                wd = _libc.inotify_add_watch(self.fd, str(p).encode(), IN_OPEN | IN_ACCESS)
                if wd < 0:      # a watch that is not there would pass every test
                    raise OSError(ctypes.get_errno(), f"inotify_add_watch {p}: {os.strerror(ctypes.get_errno())}")
                self.names[wd] = str(p)

    def opened(self) -> list[str]:
        out = set()
        while True:
            try:
                buf = os.read(self.fd, 65536)
            except BlockingIOError:
                break
            i = 0
            while i + 16 <= len(buf):
                wd, mask, _, length = struct.unpack_from("iIII", buf, i)
                if mask & (IN_OPEN | IN_ACCESS) and wd in self.names:
                    out.add(self.names[wd])
                i += 16 + length
        self.close()
        return sorted(out)

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1

    __del__ = close         # a watch left unread (its test failed first) still gives its instance back


# ------------------------------------------------------------------------------------------------ processes


def session_processes(sid: int) -> list[int]:
    """Pids of live processes in session `sid` (zombies excluded)."""
    pids = []
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            stat = Path(f"/proc/{d}/stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        if fields[0] != "Z" and int(fields[3]) == sid:
            pids.append(int(d))
    return pids


def kill_session(sid: int) -> None:
    for pid in session_processes(sid):
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass


def _limits():
    _default_signals()
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def _default_signals():
    """SIGINT as a terminal's foreground job has it: a probe started in the background (`... &`) has it ignored,
    and Python would keep it ignored in the commands, so Ctrl-C would never reach them."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


class Proc:
    """A darthand (or make) process in its own session, with its output collected."""

    def __init__(self, argv, cwd: Path, env=None, limit: bool = True):
        self.argv = argv
        self.t0 = time.perf_counter()
        env = dict(os.environ if env is None else env)
        if SOURCE != REPO:
            env["PYTHONPATH"] = str(SOURCE / "tools")
        self.p = subprocess.Popen(argv, cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, start_new_session=True, env=env,
                                  preexec_fn=_limits if limit else _default_signals)
        self.out: list[bytes] = []
        self.err: list[bytes] = []
        self._threads = [threading.Thread(target=self._drain, args=(self.p.stdout, self.out), daemon=True),
                         threading.Thread(target=self._drain, args=(self.p.stderr, self.err), daemon=True)]
        for th in self._threads:
            th.start()

    @staticmethod
    def _drain(stream, sink):
        for chunk in iter(lambda: stream.read1(65536), b""):
            sink.append(chunk)

    @property
    def stderr(self) -> str:
        return b"".join(self.err).decode(errors="replace")

    @property
    def stdout(self) -> str:
        return b"".join(self.out).decode(errors="replace")

    def wait(self, timeout: float) -> int | None:
        try:
            code = self.p.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(self.p.pid, signal.SIGKILL)
            self.p.wait()
            code = None
        for th in self._threads:
            th.join(5)
        self.seconds = time.perf_counter() - self.t0
        return code

    def wait_for(self, pattern: str, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if re.search(pattern, self.stderr + self.stdout):
                return True
            if self.p.poll() is not None:
                return False
            time.sleep(0.05)
        return False

    def orphans(self, grace: float = 3.0) -> list[int]:
        end = time.monotonic() + grace
        while time.monotonic() < end:
            left = session_processes(self.p.pid)
            if not left:
                return []
            time.sleep(0.1)
        left = session_processes(self.p.pid)
        kill_session(self.p.pid)
        return left


def judge_output(code: int | None, stderr: str, expect) -> tuple[str, str]:
    """(verdict, detail) from an exit code and stderr, without the case-specific parts."""
    if code is None:
        return "hang", "killed after the timeout"
    if code < 0:
        return "crash", f"signal {-code} ({signal.Signals(-code).name})"
    if "Traceback (most recent call last)" in stderr:
        return "traceback", _last_line(stderr)
    if code not in expect:
        return f"exit {code}", _last_line(stderr) or "(no message)"
    if code == 2 and expect == (2,) and not re.search(r"^darthand: error: .+", stderr, re.M):
        return "no message", _last_line(stderr) or "(nothing on stderr)"
    if re.search(r"leaked semaphore|Exception ignored|resource_tracker", stderr):
        return "noise", _last_line(stderr)
    return "handled", _last_line(stderr)


def _last_line(s: str) -> str:
    lines = [l for l in s.strip().splitlines() if l.strip()]
    return lines[-1][:300] if lines else ""


def fill(arg: str, t: Path, fx: Path) -> str:
    return arg.replace("{t}", str(t)).replace("{fx}", str(fx))


# ------------------------------------------------------------------------------------------------ running a case


def run_case(c: Case, t: Path, fx: Path) -> Result:
    t.mkdir(parents=True, exist_ok=True)
    res = Result(c.id, c.klass, c.name, "handled")
    try:
        if c.setup:
            c.setup(t, fx)
    except Exception as e:  # a corpus bug, not a darthand result
        res.verdict, res.detail = "setup failed", f"{type(e).__name__}: {e}"
        return res
    if c.run is not None:
        return c.run(c, t, fx, res)
    argv = [DARTHAND] + [fill(a, t, fx) for a in c.argv]
    res.argv = argv
    watch = Watch([fill(w, t, fx) for w in c.watch])
    proc = Proc(argv, t)
    code = proc.wait(c.timeout)
    opened = watch.opened()
    orphans = proc.orphans() if code is not None else []
    res.exit, res.seconds = code, proc.seconds
    verdict, detail = judge_output(code, proc.stderr, c.expect)
    canary = fill(c.canary, t, fx) if c.canary else None
    if verdict in ("hang", "crash"):
        pass
    elif opened:
        verdict, detail = "read outside", f"opened {', '.join(opened)}"
    elif canary and Path(canary).exists():
        verdict, detail = "payload ran", canary
    elif orphans:
        verdict, detail = "orphans", f"pids {orphans}"
    elif verdict == "handled" and c.check:
        problem = c.check(t, fx)
        if problem:
            verdict, detail = "check", problem
    res.verdict, res.detail = verdict, detail
    return res


# ------------------------------------------------------------------------------------------------ multi-command cases


def hidden_leftovers(folder: Path) -> list[str]:
    """Temporaries (dot-names) left under `folder`."""
    out = []
    for root, dirs, files in os.walk(folder):
        out += [os.path.join(root, n) for n in dirs + files if n.startswith(".")]
    return sorted(out)


def interrupted(argv_t, trigger: str, delay: float, out_dir: str, timeout: float = 120):
    """A run that gets Ctrl-C (SIGINT to its process group, as a terminal sends it) `delay` s after `trigger` shows:
    a regular expression on its output, 'glob:PATTERN' for a file appearing under `out_dir`, or 'start'. Handled when it
    stops with one line (exit 130 or 2), leaves no orphan and no hidden temporary in `out_dir`."""
    def run(c: Case, t: Path, fx: Path, res: Result) -> Result:
        argv = [DARTHAND] + [fill(a, t, fx) for a in argv_t]
        res.argv = argv
        proc = Proc(argv, t)
        if trigger == "start":
            seen = True
        elif trigger.startswith("glob:"):
            folder, end = Path(fill(out_dir, t, fx)), time.monotonic() + timeout
            while time.monotonic() < end and proc.p.poll() is None and not list(folder.glob(trigger[5:])):
                time.sleep(0.01)
            seen = bool(list(folder.glob(trigger[5:])))
        else:
            seen = proc.wait_for(trigger, timeout)
        if not seen or proc.p.poll() is not None:
            proc.wait(1)
            res.verdict, res.detail = "setup failed", f"finished before {trigger!r}: {_last_line(proc.stderr)}"
            return res
        time.sleep(delay)
        if proc.p.poll() is not None:
            res.verdict, res.detail = "setup failed", "finished before the interruption"
            return res
        os.killpg(proc.p.pid, signal.SIGINT)
        code = proc.wait(60)
        res.exit, res.seconds = code, proc.seconds
        orphans = proc.orphans() if code is not None else []
        verdict, detail = judge_output(code, proc.stderr, (130, 2))
        lines = [l for l in proc.stderr.splitlines() if "interrupt" in l.lower() or "error" in l.lower()]
        left = hidden_leftovers(Path(fill(out_dir, t, fx)))
        if verdict == "handled" and orphans:
            verdict, detail = "orphans", f"pids {orphans}"
        elif verdict == "handled" and len(lines) != 1:
            verdict, detail = "check", f"{len(lines)} interruption lines: {lines[:3]}"
        elif verdict == "handled" and left:
            verdict, detail = "check", f"left {left[:3]}"
        res.verdict, res.detail = verdict, detail
        return res
    return run


def killed_then_rerun(argv_t, staging_glob: str, parent: str):
    """SIGKILL while the staging folder exists, then the same command again: handled when the re-run succeeds and
    no staging folder is left beside the output."""
    def run(c: Case, t: Path, fx: Path, res: Result) -> Result:
        argv = [DARTHAND] + [fill(a, t, fx) for a in argv_t]
        res.argv = argv
        folder = Path(fill(parent, t, fx))
        proc = Proc(argv, t)
        end = time.monotonic() + 60
        while time.monotonic() < end and not list(folder.glob(staging_glob)) and proc.p.poll() is None:
            time.sleep(0.005)
        os.killpg(proc.p.pid, signal.SIGKILL)
        proc.wait(30)
        if not list(folder.glob(staging_glob)):
            res.verdict, res.detail = "setup failed", "the staging folder was never seen"
            return res
        again = Proc(argv, t)
        code = again.wait(120)
        res.exit, res.seconds = code, again.seconds
        verdict, detail = judge_output(code, again.stderr, (0,))
        left = sorted(p.name for p in folder.glob(staging_glob))
        if verdict == "handled" and left:
            verdict, detail = "check", f"staging folders left after the re-run: {left}"
        res.verdict, res.detail = verdict, detail
        return res
    return run


def damaged_build(c: Case, t: Path, fx: Path, res: Result) -> Result:
    """A build folder with a manifest whose texture PNG (hard-linked into two packages) is then truncated:
    `darthand verify` must name the damaged files and exit 1."""
    build = t / "build"
    shutil.copytree(fx / "tex", build / "textures")
    for side in ("right", "left"):
        (build / "usd" / side).mkdir(parents=True)
        os.link(build / "textures" / "brown_moles_00.png", build / "usd" / side / "brown_moles_00.png")
    proc = Proc([DARTHAND, "manifest", "--build", str(build)], t)
    proc.wait(60)
    png = build / "textures" / "brown_moles_00.png"
    stat = png.stat()
    with open(png, "r+b") as f:
        f.truncate(stat.st_size // 2)
    argv = [DARTHAND, "verify", "--build", str(build)]
    res.argv = argv
    proc = Proc(argv, t)
    code = proc.wait(60)
    res.exit, res.seconds = code, proc.seconds
    verdict, detail = judge_output(code, proc.stderr, (1,))
    named = sum(f"{p}/brown_moles_00.png" in proc.stdout + proc.stderr for p in ("textures", "usd/right", "usd/left"))
    if verdict == "handled" and named < 3:
        verdict, detail = "check", f"named {named} of the 3 damaged paths"
    res.verdict, res.detail = verdict, detail
    return res


def make_tree(t: Path) -> Path:
    """A checkout to run `make` in: the repository's sources and .venv linked, its own build/. The files the set-up
    stamps depend on are copies dated 1970, so make never re-installs the shared .venv or node_modules from here."""
    tree = t / "tree"
    tree.mkdir(parents=True)
    for name in ("Makefile", "tools", "assets_src", "schemas", ".venv", "node_modules"):
        if (SOURCE / name).exists():
            os.symlink((SOURCE / name).resolve() if name in (".venv", "node_modules") else SOURCE / name,
                       tree / name)
    for name in ("pyproject.toml", "package.json", "package-lock.json"):
        if (SOURCE / name).exists():
            shutil.copy(SOURCE / name, tree / name)
            os.utime(tree / name, (0, 0))
    return tree


def make_interrupted(c: Case, t: Path, fx: Path, res: Result) -> Result:
    """`make assets RES=64` interrupted by Ctrl-C while the textures step's worker processes run: handled when
    make stops with one interruption line per step, no traceback, no leaked-semaphore warning, no process left,
    no temporary file left under build/, and the next `make assets` gets past the interrupted step."""
    tree = make_tree(t)
    env = dict(os.environ, MAKEFLAGS="")
    argv = ["make", "assets", "RES=64", "SIDE=right"]
    res.argv = argv
    proc = Proc(argv, tree, env=env, limit=False)
    if not proc.wait_for(r"\[textures\] \.\.\.", 180):
        proc.wait(1)
        res.verdict, res.detail = "setup failed", f"textures step not reached: {_last_line(proc.stderr)}"
        return res
    time.sleep(4.0)
    os.killpg(proc.p.pid, signal.SIGINT)
    code = proc.wait(60)
    res.exit, res.seconds = code, proc.seconds
    orphans = proc.orphans(5)
    # make stops by re-raising SIGINT (exit status "killed by SIGINT") or with an error code: both are fine
    verdict, detail = judge_output(None if code is None else abs(code), proc.stderr, tuple(range(1, 256)))
    detail = " | ".join(l for l in proc.stderr.splitlines()[-6:] if l.strip())[:600]
    left = hidden_leftovers(tree / "build")
    if verdict == "handled" and orphans:
        verdict, detail = "orphans", f"pids {orphans}"
    elif verdict == "handled" and left:
        verdict, detail = "check", f"left {left[:3]}"
    res.verdict, res.detail = verdict, detail
    return res


def add_multi_command_cases() -> None:
    klass = "interruption and damage"
    case(klass, "Ctrl-C: textures build with 2 workers", run=interrupted(
        ["textures", "build", "{fx}/model/right.npz", "--out", "{t}/tex", "--res", "512", "--category", "tattoos",
         "--jobs", "2", "--no-sheet"], r"\[textures\] \d+/", 0.5, "{t}/tex"))
    case(klass, "Ctrl-C: render 4096 px", run=interrupted(
        ["render", "{fx}/model/right.npz", "--out", "{t}/out", "--size", "4096", "--samples", "16", "--textures",
         "{fx}/tex", "--camera", "{t}/camera.json"], "glob:camera.json", 6.0, "{t}"),
         setup=lambda t, fx: text(t / "camera.json", '{"view": "dorsal"}'))
    case(klass, "Ctrl-C: validate (Khronos validator running)", run=interrupted(
        ["validate"] + ["{fx}/gltf/right.gltf", "{fx}/glb/right.glb"] * 8, "start", 7.0, "{t}"))
    case(klass, "Ctrl-C: export usd", run=interrupted(
        ["export", "usd", "{fx}/model/right.npz", "--out", "{t}/usd/right", "--textures", "{fx}/tex",
         "--accessories", "{fx}/acc"], "glob:.right*", 0.05, "{t}/usd"))
    case(klass, "SIGKILL during export usd, then re-run", run=killed_then_rerun(
        ["export", "usd", "{fx}/model/right.npz", "--out", "{t}/usd/right", "--textures", "{fx}/tex",
         "--accessories", "{fx}/acc"], ".right*", "{t}/usd"))
    case(klass, "damaged output: truncated PNG hard-linked into packages", run=damaged_build)


# ------------------------------------------------------------------------------------------------ main


def table(results: list[Result]) -> str:
    by = defaultdict(list)
    for r in results:
        by[r.klass].append(r)
    lines = ["| input class | cases | handled | not handled (kind: count) |", "|---|---|---|---|"]
    for klass, rs in by.items():
        bad = Counter(r.verdict for r in rs if r.verdict != "handled")
        lines.append(f"| {klass} | {len(rs)} | {sum(r.verdict == 'handled' for r in rs)} | "
                     + (", ".join(f"{k}: {n}" for k, n in sorted(bad.items())) or "-") + " |")
    total = len(results)
    lines.append(f"| **all** | **{total}** | **{sum(r.verdict == 'handled' for r in results)}** | |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default=None, help="work folder (default: a fresh temporary folder)")
    ap.add_argument("--jobs", type=int, default=3, help="cases run at once (default 3)")
    ap.add_argument("--only", default=None, help="only cases whose class or name contains this text")
    ap.add_argument("--json", default=None, help="write every case's result to this JSON file")
    ap.add_argument("--make", action=argparse.BooleanOptionalAction, default=True,
                    help="include the `make assets` interruption case (default on)")
    ap.add_argument("--source", default=None, help="run this checkout's code instead (before/after comparisons)")
    args = ap.parse_args(argv)
    global SOURCE
    if args.source:
        SOURCE = Path(args.source).resolve()
        sys.path.insert(0, str(SOURCE / "tools"))

    add_multi_command_cases()
    if args.make:
        case("interruption and damage", "Ctrl-C: make assets during the textures step", run=make_interrupted)
    work = Path(args.work or tempfile.mkdtemp(prefix="darthand-probe-"))
    fx = build_fixtures(work / "fixtures")
    cases = [c for c in CASES if not args.only or args.only.lower() in c.id.lower()]
    cases_dir = work / "cases"
    shutil.rmtree(cases_dir, ignore_errors=True)
    t0 = time.perf_counter()
    results: list[Result] = []
    interrupts = [c for c in cases if c.klass == "interruption and damage"]
    rest = [c for c in cases if c not in interrupts]
    with cf.ThreadPoolExecutor(args.jobs) as pool:
        futures = {pool.submit(run_case, c, cases_dir / f"{i:04d}", fx): c for i, c in enumerate(rest)}
        for n, fut in enumerate(cf.as_completed(futures), 1):
            r = fut.result()
            results.append(r)
            if r.verdict != "handled":
                print(f"[{n}/{len(cases)}] {r.verdict:>12}  {r.id}  -- {r.detail[:160]}", file=sys.stderr,
                      flush=True)
    for i, c in enumerate(interrupts):        # one at a time: they time their signals
        r = run_case(c, cases_dir / f"int{i:02d}", fx)
        results.append(r)
        print(f"[int] {r.verdict:>12}  {r.id}  -- {r.detail[:160]}", file=sys.stderr, flush=True)
    order = {c.id: i for i, c in enumerate(cases)}
    results.sort(key=lambda r: order[r.id])
    print(table(results))
    print(f"\n{len(results)} cases in {time.perf_counter() - t0:.0f} s; work folder {work}")
    if args.json:
        Path(args.json).write_text(json.dumps([asdict(r) for r in results], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
