"""The Ray runner: a dataset's chunks rendered by actors spread over the nodes of a Ray cluster
(`render-dataset --ray [ADDRESS]`).

run.py plans the shards, digests the jobs, keeps the resume records and hands chunks to a runner; this one has the
interface of dataset/local.py's (`submit(chunk) -> Future`, `stop()`, `close()`), so frame i is the same job, the
same digest and the same bytes whatever the cluster.

Workers: one actor per CPU of the cluster (or `workers`), placed by Ray over the nodes (SPREAD); each opens a side's
source once, on its first chunk of that side, and renders its chunks with local.render_chunk, single-threaded, as a
local worker does. The driver keeps two chunks on each actor (one rendering, one waiting, so no actor idles on a
round trip) and the rest in its own queue, so a fast node takes more chunks than a slow one.

Files, `files`:
    auto    per node, as found (default): a node that sees the driver's input files (same path, size and
            modification time: a shared filesystem) reads them there; one that does not gets them through Ray's
            object store, only those its chunks need (the model, the catalogue files, the textures, accessories,
            background images and pose/lights/camera files its jobs use), kept in a node-local cache for the run.
            A node that sees the output folder (a probe file the driver wrote there) writes its frames into it;
            one that does not renders into node-local staging and returns the encoded files to the driver, which
            writes them atomically (labels last, as a local worker does).
    shared  every node must see everything: a node that does not is a one-line error before anything renders.
    ship    every node gets its inputs through Ray and returns its frames (no shared filesystem assumed).
A group of files (a catalogue and the textures or accessories it lists, a USD package folder, a background folder)
is either seen or shipped as a whole on a node, so paths inside it stay relative to it.

Node loss: an actor that dies (its node lost, killed) has its chunks queued again, without the frames it had
finished (their labels carry the job's digest), so nothing is rendered or written twice but the frame it was
writing; a replacement actor is asked for and joins when the cluster has a CPU for it. A chunk whose actors died
MAX_ATTEMPTS times stops the run.

Clocks: results carry the worker's monotonic time; the driver rebases frame times on its own clock (offset taken
when a result arrives, off by the result's transit time, milliseconds), so run.py's timings and rates hold across
machines. Results also name their node, for the per-node progress.
"""

from __future__ import annotations

import hashlib
import json
import os
import queue
import shutil
import socket
import tempfile
import threading
import time
from concurrent.futures import Future
from dataclasses import replace
from pathlib import Path

from darthand.errors import InputError

FILES_MODES = ("auto", "shared", "ship")
PER_ACTOR = 2                     # chunks in flight per actor
MAX_ATTEMPTS = 3                  # actors lost on one chunk before the run stops
START_TIMEOUT_S = 300.0           # for the first actor to be up (imports, a busy cluster)
GATHER_S = 30.0                   # then for the others, before rendering starts without them
STOP_GRACE_S = 10.0               # close(): how long running chunks get to finish their frame
CONNECT_TIMEOUT_S = 10.0
CACHE = "darthand-ray"            # node-local folder (in the temp dir) of shipped inputs and staged outputs


def connect(address: str | None):
    """(the `ray` module, whether this call connected it), connected to the cluster at `address` ('host:port' of
    its head, 'auto', or None: RAY_ADDRESS, else the cluster started on this machine, else a new local one).
    InputError when Ray is not installed or no cluster answers."""
    try:
        import ray
    except ImportError:
        raise InputError("--ray: Ray is not installed (pip install 'darthand[cluster]', or `make venv` in a "
                         "checkout)") from None
    if ray.is_initialized():
        return ray, False
    _check_reachable(address)
    import logging

    try:
        ray.init(address=address or None, logging_level=logging.ERROR, log_to_driver=False,
                 include_dashboard=False if not address else None)
    except Exception as e:                    # Ray raises ConnectionError, RuntimeError, ValueError...
        first = (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise InputError(f"--ray {address or ''}: cannot connect to a Ray cluster ({first})".replace("  ", " ")) \
            from None
    return ray, True


def _check_reachable(address: str | None) -> None:
    """A quick TCP check of a 'host:port' address (ray.init waits a minute on an address nobody answers)."""
    if not address or address == "auto" or "://" in address:
        return
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise InputError(f"--ray {address}: not an address of the form HOST:PORT (the head node's, e.g. "
                         "10.0.0.1:6379) or 'auto'")
    try:
        socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as e:
        raise InputError(f"--ray {address}: no Ray cluster answers there ({e.strerror or e})") from None


def code_digest() -> str:
    """sha256 (16 hex digits) of darthand's Python sources and the versions of the libraries a frame's bytes depend
    on: nodes must agree on it for frames to be the same bytes on every node."""
    import embreex
    import numba
    import numpy
    import OpenImageIO

    import darthand

    h = hashlib.sha256()
    root = Path(darthand.__file__).parent
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    for module in (numpy, numba, embreex, OpenImageIO):     # numba compiles darthand/jit.py's kernels
        h.update(f"{module.__name__} {getattr(module, '__version__', '?')}".encode())
    return h.hexdigest()[:16]


def fingerprint(path: Path) -> list[int] | None:
    """[size, mtime_ns] of a file, or None when it is not one."""
    try:
        st = path.stat()
    except OSError:
        return None
    return [st.st_size, st.st_mtime_ns] if path.is_file() else None


# ------------------------------------------------------------------------------------------------ driver side


class InputFiles:
    """The input files of a run, by group (module docstring), as the driver sees them.

    specs: {side: SourceSpec} with every path made absolute; open_files: {side: [(path, group)]} what opening a
    side's source reads; per chunk, `needed(chunk)` adds what its jobs use (textures, accessories, backgrounds,
    pose/lights/camera files)."""

    def __init__(self, specs: dict, sources: dict):
        from darthand.render.assets import default_catalogues

        self.sources = sources
        self.specs, self.open_files, self.labels = {}, {}, {}
        self._catalogue_files: dict = {}
        self._fingerprints: dict = {}
        for side, spec in specs.items():
            package = Path("build") / "model" / f"{spec.package}.npz" if spec.package in ("right", "left") \
                else Path(spec.package)
            files: list = []
            pkg = _absolute(package) if package.exists() else spec.package
            tex, acc, model = spec.textures, spec.accessories, spec.model
            if package.is_dir():
                files += [(p, f"dir:{pkg}") for p in sorted(Path(pkg).rglob("*")) if p.is_file()]
            elif package.is_file():
                files.append((Path(pkg), f"file:{pkg}"))
                if package.suffix == ".npz" and (tex is None or acc is None):
                    found = default_catalogues(package)
                    tex, acc = tex if tex is not None else found[0], acc if acc is not None else found[1]
            tex = self._catalogue(tex, files, "textures")
            acc = self._catalogue(acc, files, "accessories")
            if model is not None and Path(model).is_file():
                model = _absolute(model)
                files.append((Path(model), f"file:{model}"))
            self.specs[side] = replace(spec, package=str(pkg), textures=tex, accessories=acc, model=model)
            self.open_files[side] = files
            src = sources.get(side) if sources else None
            self.labels[side] = None if src is None else str(getattr(src, "interface", None) or src.source)

    def _catalogue(self, path, files: list, kind: str):
        """The catalogue file (absolute) of a catalogue path (file or folder); its open-time files added."""
        if not path:
            return path
        cat = Path(path) / "catalog.json" if Path(path).is_dir() else Path(path)
        if not cat.is_file():
            return str(path)                       # opening it fails with the loader's own error
        cat = Path(_absolute(cat))
        group = f"catalog:{cat}"
        files.append((cat, group))
        if kind == "accessories":
            try:
                doc = json.loads(cat.read_text())
                files += [(cat.parent / e["files"]["npz"], group) for e in doc.get("accessories", [])]
            except (OSError, ValueError, KeyError, TypeError):
                pass                               # the loader reports a broken catalogue
        self._catalogue_files[kind, str(cat)] = group
        return str(cat)

    def needed(self, items: list, sides: set) -> dict:
        """{path: [group, size, mtime_ns]} of the files a chunk [(job, digest)] reads: its sides' open-time files,
        its textures and accessories, backgrounds and pose/lights/camera files."""
        out: dict = {}

        def add(path, group):
            path = _absolute(path)
            if path not in self._fingerprints:            # inputs do not change during a run: stat each once
                self._fingerprints[path] = fingerprint(Path(path))
            if self._fingerprints[path] is not None:
                out[path] = [group, *self._fingerprints[path]]

        for side in sides:
            for path, group in self.open_files.get(side, ()):
                add(path, group)
        for job, _ in items:
            side = job.get("side") or next(iter(self.specs))
            src = self.sources.get(side) if self.sources else None
            spec = self.specs.get(side)
            textures = getattr(src, "textures", None)
            if isinstance(textures, dict) and spec is not None and spec.textures:
                t = textures.get(job.get("texture") or getattr(src, "default_texture", None))
                group = self._catalogue_files.get(("textures", spec.textures))
                for path in (getattr(t, "albedo", None), getattr(t, "roughness", None)):
                    if path is not None and group:
                        add(path, group)
            accessories = getattr(src, "accessories", None)
            if isinstance(accessories, dict) and spec is not None and spec.accessories:
                a = accessories.get(job.get("accessory") or "none")
                group = self._catalogue_files.get(("accessories", spec.accessories))
                for path in (getattr(a, "base_color_png", None), getattr(a, "metallic_roughness_png", None)):
                    if path is not None and group:
                        add(path, group)
            for key in ("pose", "lights", "camera"):
                value = job.get(key)
                if isinstance(value, str) and os.path.isabs(value):     # a file (names are gestures, views)
                    add(value, f"file:{value}")
            bg = job.get("background")
            if isinstance(bg, dict) and bg.get("folder"):
                folder = _absolute(bg["folder"])
                for name in bg.get("files", []):
                    add(Path(folder) / name, f"dir:{folder}")
        return out


def _absolute(path) -> str:
    return os.path.abspath(os.fspath(path))


class RayRunner:
    """Chunks on actors over a Ray cluster (module docstring).

    specs: {side: SourceSpec}; sources: {side: opened source} (the driver's: the labels' source names, and which
    files a texture or accessory id reads); settings: run.py's (out_dir, size, samples, aa_shading); address, files:
    see `connect` and the module docstring; workers: actors (default: the cluster's CPUs)."""

    def __init__(self, specs: dict, settings: dict, sources: dict | None = None, address: str | None = None,
                 files: str = "auto", workers: int | None = None):
        self.specs_given = specs
        if files not in FILES_MODES:
            raise InputError(f"--ray-files: {files!r} is not one of {', '.join(FILES_MODES)}")
        self.address, self.files_mode = address or "auto", files
        self.out = Path(settings["out_dir"]).resolve()
        self.settings = {**settings, "out_dir": str(self.out)}
        self.token = hashlib.sha256(str(self.out).encode()).hexdigest()[:12]
        self._probe = self.out / "shards" / f".ray-probe.{self.token}"
        self.actors: dict = {}                 # actor handle -> {"info", "inflight": set of refs}
        self._greeted: list = []               # every actor that started (close() cleans their caches)
        self._pending: dict = {}               # hello ref -> actor handle
        self._inflight: dict = {}              # ref -> (actor, entry)
        self._queue: list = []                 # entries waiting for an actor
        self._submitted: queue.Queue = queue.Queue()
        self._refs: dict = {}                  # path -> ObjectRef of its bytes (shipped files)
        self._shipped: dict = {}               # path -> bytes shipped
        self._lost = 0
        self._stopping = threading.Event()
        self._closed = False
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self.nodes: dict = {}                  # node key -> {"ip", "host", "actors", "inputs", "outputs"}
        self.ray, self._owns_connection = connect(address)
        try:
            self._start(sources, workers)
        except BaseException:
            self.close()
            raise
        self._thread = threading.Thread(target=self._loop, daemon=True, name="darthand-ray-dispatch")
        self._thread.start()

    def _start(self, sources, workers) -> None:
        """The probe file, the actors (one per cluster CPU unless `workers`), their hellos."""
        self.inputs = InputFiles(self.specs_given, sources or {})
        nonce = os.urandom(8).hex()
        self._probe.write_text(nonce)
        self.digest = code_digest()
        cpus = int(self.ray.cluster_resources().get("CPU", 0))
        if cpus < 1 and not workers:
            raise InputError(f"--ray {self.address}: the cluster has no CPUs to render on")
        self.processes = int(workers or cpus)
        self._actor_class = self.ray.remote(num_cpus=1, max_restarts=0,
                                            concurrency_groups={"control": 1})(NodeWorker)
        self._config = (self.inputs.specs, self.settings, self.inputs.labels, self.token, nonce, str(self._probe),
                        self.files_mode, {side: self.inputs.needed([], {side}) for side in self.inputs.specs})
        for _ in range(self.processes):
            self._new_actor()
        self._await_actors()

    # -------------------------------------------------------------------------------------------- actors

    def _new_actor(self) -> None:
        actor = self._actor_class.options(scheduling_strategy="SPREAD").remote(*self._config)
        self._pending[actor.hello.remote()] = actor

    def _await_actors(self) -> None:
        """Wait for the actors' hellos: up to START_TIMEOUT_S for the first, then GATHER_S more for the others (those
        still waiting for a CPU join later). Errors of the files check (files='shared') and of mismatched code stop
        the run here, before anything renders."""
        deadline = time.monotonic() + START_TIMEOUT_S
        while self._pending:
            if self.actors:
                deadline = min(deadline, self._first_hello + GATHER_S)
            left = deadline - time.monotonic()
            if left <= 0 and self.actors:
                break
            if left <= 0:
                raise InputError(f"--ray {self.address}: no worker started on the cluster within "
                                 f"{START_TIMEOUT_S:.0f} s (are its CPUs busy with other jobs?)")
            ready, _ = self.ray.wait(list(self._pending), num_returns=1, timeout=min(left, 1.0))
            for ref in ready:
                self._greet(ref)

    def _greet(self, ref) -> None:
        """An actor's hello arrived: check it, add it to the active actors."""
        actor = self._pending.pop(ref)
        try:
            info = self.ray.get(ref)
        except self.ray.exceptions.RayActorError:
            self._lost += 1
            return
        self._greeted.append(actor)
        if "error" in info:
            raise InputError(info["error"])
        if info["code"] != self.digest:
            raise InputError(f"--ray: node {info['ip']} ({info['node'][:8]}) runs another darthand or other "
                             f"libraries (code {info['code']}, here {self.digest}): install the same version on "
                             "every node")
        if not self.actors:
            self._first_hello = time.monotonic()
        self.actors[actor] = {"info": info, "inflight": set(), "opened": set()}
        node = self.nodes.setdefault(info["node"][:8], {"ip": info["ip"], "host": info["host"], "actors": 0,
                                                        "inputs": info["inputs"], "outputs": info["outputs"]})
        node["actors"] += 1

    def describe(self) -> dict:
        """What dataset.json records of the runner: its kind, the address, the files mode, the nodes used."""
        return {"kind": "ray", "address": self.address, "files": self.files_mode, "actors": len(self.actors),
                "nodes": self.nodes, "actors_lost": self._lost,
                "shipped": {"files": len(self._shipped), "mb": round(sum(self._shipped.values()) / 2**20, 3),
                            "paths": sorted(self._shipped)[:1000]}}

    # -------------------------------------------------------------------------------------------- runner interface

    def submit(self, chunk: list) -> Future:
        future: Future = Future()
        if self._error is not None:
            future.set_exception(self._error)
            return future
        self._submitted.put({"items": chunk, "future": future, "attempts": 0, "recovered": [], "ship": set()})
        return future

    def stop(self) -> None:
        """Ask every actor to stop after its current frame and drop the queued chunks (Ctrl-C, a failed frame)."""
        self._stopping.set()
        for actor in list(self.actors):
            try:
                actor.stop.options(concurrency_group="control").remote()      # beside the running chunk
            except Exception:              # an actor already gone
                pass

    def close(self) -> None:
        """Stop dispatching, give running chunks STOP_GRACE_S to end, clean the nodes' caches, end the actors and
        the connection."""
        if self._closed:
            return
        self._closed = True
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(timeout=STOP_GRACE_S + 5)
        ray = getattr(self, "ray", None)
        if ray is None:
            return
        if self._inflight:
            ray.wait(list(self._inflight), num_returns=len(self._inflight), timeout=STOP_GRACE_S)
        cleanups = []
        for actor in self._greeted:
            try:
                cleanups.append(actor.cleanup.options(concurrency_group="control").remote())
            except Exception:
                pass
        if cleanups:
            ray.wait(cleanups, num_returns=len(cleanups), timeout=STOP_GRACE_S)
        for actor in self._greeted + list(self._pending.values()):
            try:
                ray.kill(actor)
            except Exception:
                pass
        self._probe.unlink(missing_ok=True)
        for entry in self._queue + self._drain_submitted():
            entry["future"].cancel()
        if self._owns_connection:
            ray.shutdown()

    def _drain_submitted(self) -> list:
        entries = []
        while True:
            try:
                entries.append(self._submitted.get_nowait())
            except queue.Empty:
                return entries

    # -------------------------------------------------------------------------------------------- dispatch loop

    def _loop(self) -> None:
        """The driver's dispatcher: queue submitted chunks, hand them to actors with room, collect results."""
        ray = self.ray
        try:
            while not self._stopping.is_set():
                self._queue += self._drain_submitted()
                self._dispatch()
                waiting = list(self._inflight) + list(self._pending)
                if not waiting:
                    try:
                        self._queue.append(self._submitted.get(timeout=0.05))
                    except queue.Empty:
                        pass
                    continue
                ready, _ = ray.wait(waiting, num_returns=1, timeout=0.05)
                if ready:
                    ready, _ = ray.wait(waiting, num_returns=len(waiting), timeout=0)
                for ref in ready:                       # a lost actor's other chunks may be requeued already
                    if ref in self._pending:
                        self._greet(ref)
                    elif ref in self._inflight:
                        self._collect(ref)
        except BaseException as e:                    # fail every waiting chunk with the error, once
            self._error = e if isinstance(e, InputError) else InputError(f"--ray: {type(e).__name__}: {e}")
            for _, entry in list(self._inflight.values()) + [(None, e2) for e2 in self._queue]:
                if not entry["future"].done():
                    entry["future"].set_exception(self._error)
            for entry in self._drain_submitted():
                entry["future"].set_exception(self._error)

    def _dispatch(self) -> None:
        """Queued chunks to the actors with the fewest in flight (below PER_ACTOR)."""
        while self._queue and self.actors:
            actor = min(self.actors, key=lambda a: len(self.actors[a]["inflight"]))
            if len(self.actors[actor]["inflight"]) >= PER_ACTOR:
                return
            entry = self._queue.pop(0)
            items = entry["items"]
            sides = {job.get("side") or next(iter(self.inputs.specs)) for job, _ in items}
            needed = self.inputs.needed(items, sides - self.actors[actor]["opened"])
            refs = {path: self._ref(path) for path in entry["ship"]}
            ref = actor.render.remote(items, needed, refs)
            self.actors[actor]["inflight"].add(ref)
            self._inflight[ref] = (actor, entry)

    def _ref(self, path: str):
        """The object-store copy of a file's bytes, put once per run."""
        if path not in self._refs:
            data = Path(path).read_bytes()
            self._refs[path] = self.ray.put(data)
            self._shipped[path] = len(data)
        return self._refs[path]

    def _collect(self, ref) -> None:
        actor, entry = self._inflight.pop(ref)
        state = self.actors.get(actor)
        if state is not None:
            state["inflight"].discard(ref)
        try:
            result = self.ray.get(ref)
        except self.ray.exceptions.RayActorError:
            self._actor_lost(actor, entry)
            return
        if "need" in result:                           # files this node must get through Ray: send them along
            entry["ship"] |= set(result["need"])
            self._queue.insert(0, entry)
            return
        if "error" in result:
            raise InputError(result["error"])
        opened = result.pop("opened", ())
        if state is not None:
            state["opened"] |= set(opened)
        self._write_returned(result.pop("files", None) or [])
        offset = time.monotonic() - result.pop("now")
        for frame in result["frames"]:
            frame["end"] += offset
        result["frames"] += entry["recovered"]
        entry["future"].set_result(result)

    def _write_returned(self, files: list) -> None:
        """Write the files a node returned, atomically, in its order (each frame's labels last)."""
        from darthand.fileio import write_bytes

        for name, data in files:
            path = (self.out / name).resolve()
            if self.out not in path.parents:
                raise InputError(f"--ray: a worker returned a file outside the output folder: {name}")
            write_bytes(path, data)

    def _actor_lost(self, actor, entry) -> None:
        """An actor died with `entry` on it: keep the frames it finished, queue the rest again, ask for a
        replacement actor."""
        from darthand.dataset.frames import existing_frame

        if actor in self.actors:
            info = self.actors.pop(actor)["info"]
            self._lost += 1
            self.nodes[info["node"][:8]]["lost"] = True
            for other_ref, (other_actor, other_entry) in list(self._inflight.items()):
                if other_actor is actor:
                    del self._inflight[other_ref]
                    self._actor_lost(actor, other_entry)
            self._new_actor()
        entry["attempts"] += 1
        todo = []
        for job, digest in entry["items"]:
            found = existing_frame(self.out, job, digest)
            if found is None:
                todo.append((job, digest))
            else:
                entry["recovered"].append(found)
        if not todo:
            entry["future"].set_result({"pid": None, "node": None, "open_s": 0.0, "frames": entry["recovered"],
                                        "steps": {}, "maxrss_mb": 0.0})
            return
        if entry["attempts"] >= MAX_ATTEMPTS:
            raise InputError(f"frame {todo[0][0]['index']}: {MAX_ATTEMPTS} Ray workers died rendering its chunk")
        entry["items"] = todo
        self._queue.insert(0, entry)


# ------------------------------------------------------------------------------------------------ node side


class NodeWorker:
    """The actor: renders chunks on its node with local.render_chunk (this process is dedicated to it, so it holds
    local's per-process state). Files are resolved per group, seen or shipped (module docstring).

    specs: {side: SourceSpec} with the driver's absolute paths; settings: run.py's; labels: {side: the source name
    the labels carry, as a local run writes it}; token: the run's (names the node-local cache, so a resumed run
    finds what was shipped before); nonce, probe: the output folder's probe file and its content; files: the mode;
    open_files: {side: {path: [group, size, mtime_ns]}} what opening a side reads."""

    def __init__(self, specs: dict, settings: dict, labels: dict, token: str, nonce: str, probe: str, files: str,
                 open_files: dict):
        from darthand.dataset import local

        self.specs, self.labels, self.files_mode, self.open_files = specs, labels, files, open_files
        self.out_dir = settings["out_dir"]
        root = Path(tempfile.gettempdir()) / CACHE / token
        self.cache = root / "files"
        self.sees_output = files != "ship" and _read(probe) == nonce
        if not self.sees_output:
            root.mkdir(parents=True, exist_ok=True)
            self.staging = Path(tempfile.mkdtemp(prefix="out-", dir=root))
        self.groups: dict = {}                 # group -> "seen" | "shipped"
        self.where: dict = {}                  # driver path -> the path this node reads
        self.opened: set = set()
        out_dir = settings["out_dir"] if self.sees_output else str(self.staging)
        self.state = local.set_worker_state(specs, {**settings, "out_dir": out_dir}, 1, threading.Event())

    def hello(self) -> dict:
        """Who this actor is, and whether its node sees the inputs and the output folder (an 'error' when files is
        'shared' and it does not)."""
        import ray

        ctx = ray.get_runtime_context()
        self.node = {"node": ctx.get_node_id(), "ip": ray.util.get_node_ip_address(), "host": socket.gethostname()}
        info = {**self.node, "pid": os.getpid(), "code": code_digest(),
                "outputs": "direct" if self.sees_output else "returned"}
        try:
            if self.files_mode == "shared" and not self.sees_output:
                raise InputError(f"--ray-files shared: node {self.node['ip']} ({self.node['node'][:8]}) does not see "
                                 f"the output folder {self.out_dir} (a shared filesystem is "
                                 "needed; --ray-files auto returns frames through Ray)")
            for needed in self.open_files.values():
                for path, (group, size, mtime) in needed.items():
                    self._decide(group, path, [size, mtime])
        except InputError as e:
            return {**info, "error": str(e)}
        states = set(self.groups.values())
        info["inputs"] = "shared" if states <= {"seen"} else "shipped" if states == {"shipped"} else "mixed"
        return info

    def render(self, items: list, needed: dict, refs: dict) -> dict:
        """Render a chunk [(job, digest)]: its result (local.render_chunk's, plus the node, its clock, and the
        frames' files when this node does not see the output folder), {'need': [paths]} when files must be
        shipped first, or {'error': message}."""
        from darthand.dataset import local

        try:
            missing = self._resolve(needed, refs)
            if missing:
                return {"need": missing}
            default = next(iter(self.specs))
            for side in dict.fromkeys(job.get("side") or default for job, _ in items):
                self._open(side)
            result = local.render_chunk([(self._node_job(job), digest) for job, digest in items])
            if not self.sees_output:
                result["files"] = self._take_staged(result["frames"])
        except InputError as e:
            return {"error": str(e)}
        except Exception as e:                     # a broken cache, a full disk: one line naming the node
            return {"error": f"--ray: node {self.node['ip']} ({self.node['node'][:8]}): {type(e).__name__}: {e}"}
        result.update(node=self.node["node"][:8], ip=self.node["ip"], opened=sorted(self.opened), now=time.monotonic())
        return result

    def stop(self) -> None:
        self.state["stop"].set()

    def cleanup(self) -> None:
        """Remove this run's node-local cache and staging (the run is over), and CACHE itself once no run uses it."""
        shutil.rmtree(self.cache.parent, ignore_errors=True)
        try:
            self.cache.parent.parent.rmdir()
        except OSError:                            # another run's cache is there, or already removed
            pass

    # -------------------------------------------------------------------------------------------- files

    def _decide(self, group: str, path: str, fp: list) -> str:
        """A group's state on this node, decided on its first file: seen (the driver's file is here), or shipped."""
        if group not in self.groups:
            if self.files_mode == "ship":
                self.groups[group] = "shipped"
            elif fingerprint(Path(path)) == fp:
                self.groups[group] = "seen"
            elif self.files_mode == "shared":
                what = "does not see" if not Path(path).exists() else "sees another file at"
                raise InputError(f"--ray-files shared: node {self.node['ip']} ({self.node['node'][:8]}) {what} "
                                 f"{path} (a shared filesystem is needed; --ray-files auto ships the files "
                                 "through Ray)")
            else:
                self.groups[group] = "shipped"
        return self.groups[group]

    def _resolve(self, needed: dict, refs: dict) -> list:
        """Where this node reads each needed file; fetches shipped ones into the cache. Returns the paths still to
        be shipped (not cached here and not in refs)."""
        import ray

        missing = []
        for path, (group, size, mtime) in needed.items():
            if self.where.get(path, (None,))[1:] == (size, mtime):
                continue
            if self._decide(group, path, [size, mtime]) == "seen":
                if fingerprint(Path(path)) != [size, mtime]:
                    raise InputError(f"--ray: node {self.node['ip']} ({self.node['node'][:8]}) sees {path} but "
                                     "not the driver's copy of it (a stale copy? --ray-files ship sends the files)")
                self.where[path] = (path, size, mtime)
                continue
            cached = self.cache / path.lstrip("/")
            if fingerprint(cached) != [size, mtime]:
                if path not in refs:
                    missing.append(path)
                    continue
                from darthand.fileio import write_bytes

                write_bytes(cached, ray.get(refs[path]))
                os.utime(cached, ns=(mtime, mtime))
            self.where[path] = (str(cached), size, mtime)
        return missing

    def _node_path(self, path: str | None, group: str) -> str | None:
        """A driver path that is the root of `group`, as this node reads it."""
        if not path or not os.path.isabs(path) or self.groups.get(group) != "shipped":
            return path
        return str(self.cache / path.lstrip("/"))

    def _open(self, side: str) -> None:
        """Open a side's source from where this node reads it; its labels name it as the driver does."""
        from darthand.dataset import local

        if side in self.opened:
            return
        spec = self.specs[side]
        package = self._node_path(spec.package, f"dir:{spec.package}" if f"dir:{spec.package}" in self.groups
                                  else f"file:{spec.package}")
        self.state["specs"][side] = replace(
            spec, package=package, textures=self._node_path(spec.textures, f"catalog:{spec.textures}"),
            accessories=self._node_path(spec.accessories, f"catalog:{spec.accessories}"),
            model=self._node_path(spec.model, f"file:{spec.model}"))
        source = local.worker_renderer(side).source
        label = self.labels.get(side)
        if label is not None:
            if hasattr(source, "interface"):
                source.interface = Path(label)
            else:
                source.source = label
        self.opened.add(side)

    def _node_job(self, job: dict) -> dict:
        """The job with the files it names as this node reads them."""
        job = dict(job)
        for key in ("pose", "lights", "camera"):
            value = job.get(key)
            if isinstance(value, str) and value in self.where:
                job[key] = self.where[value][0]
        bg = job.get("background")
        if isinstance(bg, dict) and bg.get("folder"):
            folder = _absolute(bg["folder"])
            job["background"] = {**bg, "folder": self._node_path(folder, f"dir:{folder}")}
        return job

    def _take_staged(self, frames: list) -> list:
        """[(name, bytes)] of the staged frames' files in the order a local worker writes them (labels last),
        removed from the staging folder."""
        from darthand.dataset.frames import frame_names

        out = []
        for frame in frames:
            names = frame_names(frame["index"])
            for kind in ("vertices", "image", "mask", "labels"):
                path = self.staging / names[kind]
                out.append((names[kind], path.read_bytes()))
                path.unlink()
        return out


def _read(path: str) -> str | None:
    try:
        return Path(path).read_text()
    except OSError:
        return None
