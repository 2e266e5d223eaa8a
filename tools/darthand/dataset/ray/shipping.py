"""Which input files the nodes of a Ray run read, and how they get them (`--ray-files`, `files`):
    auto    per node, as found (default): a node that sees the driver's input files (same path, size and
            modification time: a shared filesystem) reads them there; one that does not gets them through Ray's
            object store, only those its chunks need (the model, the catalogue files, the textures, accessories,
            background images and pose/lights/camera files its jobs use, the object catalogue once a job holds an
            object), kept in a node-local cache for the run.
            A node that sees the output folder (a probe file the driver wrote there) writes its frames into it;
            one that does not renders into node-local staging and returns the encoded files to the driver, which
            writes them atomically (labels last, as a local worker does).
    shared  every node must see everything: a node that does not is a one-line error before anything renders.
    ship    every node gets its inputs through Ray and returns its frames (no shared filesystem assumed).

A group of files (a catalogue and the textures, accessories or object meshes it lists, a USD package folder, a
background folder)
is either seen or shipped as a whole on a node, so paths inside it stay relative to it. Groups are named by kind
and root: 'file:<path>', 'dir:<folder>', 'catalog:<catalog.json>'.

InputFiles is the driver's side (what a chunk needs, with fingerprints), NodeFiles a node's (where it reads each
file: seen, or shipped into its cache). The grasp catalogue stays on the driver: the plan refits a grasp into the
job (the hand's pose, the object's placement), so a node renders an object frame from its job and the object
catalogue alone.
"""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path

from darthand.dataset.jobs import job_hands, job_objects
from darthand.errors import InputError
from darthand.fileio import write_bytes
from darthand.render.assets import default_catalogues

FILES_MODES = ("auto", "shared", "ship")


def fingerprint(path: Path) -> list[int] | None:
    """[size, mtime_ns] of a file, or None when it is not one."""
    try:
        st = path.stat()
    except OSError:
        return None
    return [st.st_size, st.st_mtime_ns] if path.is_file() else None


def absolute(path) -> str:
    return os.path.abspath(os.fspath(path))


class InputFiles:
    """The input files of a run, by group (module docstring), as the driver sees them.

    specs: {side: SourceSpec} with every path made absolute; open_files: {side: [(path, group)]} what opening a
    side's source reads; per chunk, `needed(chunk)` adds what its jobs use (textures, accessories, backgrounds,
    pose/lights/camera files, the object catalogue `objects` (its catalog.json, absolute, as `objects_catalog`
    names it) for a job holding an object)."""

    def __init__(self, specs: dict, sources: dict, objects: str | None = None):
        self.sources = sources
        self.specs, self.open_files, self.labels = {}, {}, {}
        self._catalogue_files: dict = {}
        self._fingerprints: dict = {}
        self.objects_catalog, self.object_files = catalogue_files(objects, "objects", ("npz", "base_color"))
        for side, spec in specs.items():
            package = Path("build") / "model" / f"{spec.package}.npz" if spec.package in ("right", "left") \
                else Path(spec.package)
            files: list = []
            pkg = absolute(package) if package.exists() else spec.package
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
                model = absolute(model)
                files.append((Path(model), f"file:{model}"))
            self.specs[side] = replace(spec, package=str(pkg), textures=tex, accessories=acc, model=model)
            self.open_files[side] = files
            src = sources.get(side) if sources else None
            self.labels[side] = None if src is None else str(getattr(src, "interface", None) or src.source)

    def _catalogue(self, path, files: list, kind: str):
        """The catalogue file (absolute) of a catalogue path (file or folder); its open-time files added (the
        accessories' meshes; the textures' images are a job's)."""
        cat, found = catalogue_files(path, kind, ("npz",) if kind == "accessories" else ())
        if found:
            files += found
            self._catalogue_files[kind, cat] = found[0][1]
        return cat

    def needed(self, items: list, sides: set) -> dict:
        """{path: [group, size, mtime_ns]} of the files a chunk [(job, digest)] reads: its sides' open-time files,
        its textures and accessories, backgrounds and pose/lights/camera files."""
        out: dict = {}

        def add(path, group):
            path = absolute(path)
            if path not in self._fingerprints:            # inputs do not change during a run: stat each once
                self._fingerprints[path] = fingerprint(Path(path))
            if self._fingerprints[path] is not None:
                out[path] = [group, *self._fingerprints[path]]

        for side in sides:
            for path, group in self.open_files.get(side, ()):
                add(path, group)
        for job, _ in items:
            for path, group in self._job_files(job):
                add(path, group)
            if job_objects(job):
                for path, group in self.object_files:
                    add(path, group)
        return out

    def _job_files(self, job: dict):
        """(path, group) of the files one job reads beyond its side's open-time files."""
        for hand in job_hands(job):
            yield from self._hand_files(hand)
        for key in ("lights", "camera"):
            value = job.get(key)
            if isinstance(value, str) and os.path.isabs(value):     # a file (names are views)
                yield value, f"file:{value}"
        bg = job.get("background")
        if isinstance(bg, dict) and bg.get("folder"):
            folder = absolute(bg["folder"])
            for name in bg.get("files", []):
                yield Path(folder) / name, f"dir:{folder}"


    def _hand_files(self, hand: dict):
        """(path, group) of the files one hand of a job reads (a one-hand job, or a bodies item): its texture,
        accessory and pose files."""
        side = hand.get("side") or next(iter(self.specs))
        src = self.sources.get(side) if self.sources else None
        spec = self.specs.get(side)
        textures = getattr(src, "textures", None)
        if isinstance(textures, dict) and spec is not None and spec.textures:
            t = textures.get(hand.get("texture") or getattr(src, "default_texture", None))
            group = self._catalogue_files.get(("textures", spec.textures))
            for path in (getattr(t, "albedo", None), getattr(t, "roughness", None)):
                if path is not None and group:
                    yield path, group
        accessories = getattr(src, "accessories", None)
        if isinstance(accessories, dict) and spec is not None and spec.accessories:
            a = accessories.get(hand.get("accessory") or "none")
            group = self._catalogue_files.get(("accessories", spec.accessories))
            for path in (getattr(a, "base_color_png", None), getattr(a, "metallic_roughness_png", None)):
                if path is not None and group:
                    yield path, group
        pose = hand.get("pose")
        if isinstance(pose, str) and os.path.isabs(pose):     # a file (names are gestures)
            yield pose, f"file:{pose}"


def catalogue_files(path, kind: str, names: tuple = ()) -> tuple[str | None, list]:
    """(catalog.json's absolute path, [(file, group)]: the catalogue and, for each entry of its `kind` list, the files
    its 'files' names under `names`) of a catalogue (its file or folder); (path, []) when there is none there (a run
    without it, or one the loader will refuse with its own error)."""
    if not path:
        return path, []
    cat = Path(path) / "catalog.json" if Path(path).is_dir() else Path(path)
    if not cat.is_file():
        return str(path), []
    cat = Path(absolute(cat))
    group = f"catalog:{cat}"
    files = [(cat, group)]
    if not names:
        return str(cat), files
    try:
        for entry in json.loads(cat.read_text()).get(kind, []):
            files += [(cat.parent / entry["files"][name], group) for name in names if entry["files"].get(name)]
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        pass                                       # the loader reports a broken catalogue
    return str(cat), files


class NodeFiles:
    """Where one node reads a run's input files (module docstring): a group's state, 'seen' or 'shipped', is decided
    on its first file; shipped files are fetched from Ray's object store into `cache` (a node-local folder, kept for
    the run under the same names as the driver's paths).

    mode: one of FILES_MODES; cache: Path; node: {'node': id, 'ip': address} of this node (names it in errors), set
    once known."""

    def __init__(self, mode: str, cache: Path):
        self.mode, self.cache = mode, cache
        self.node: dict = {"node": "?", "ip": "?"}
        self.groups: dict = {}                 # group -> "seen" | "shipped"
        self.where: dict = {}                  # driver path -> (the path this node reads, size, mtime_ns)

    def _name(self) -> str:
        return f"{self.node['ip']} ({self.node['node'][:8]})"

    def decide(self, group: str, path: str, fp: list) -> str:
        """A group's state on this node, decided on its first file: seen (the driver's file is here), or shipped."""
        if group not in self.groups:
            if self.mode == "ship":
                self.groups[group] = "shipped"
            elif fingerprint(Path(path)) == fp:
                self.groups[group] = "seen"
            elif self.mode == "shared":
                what = "does not see" if not Path(path).exists() else "sees another file at"
                raise InputError(f"--ray-files shared: node {self._name()} {what} {path} (a shared filesystem is "
                                 "needed; --ray-files auto ships the files through Ray)")
            else:
                self.groups[group] = "shipped"
        return self.groups[group]

    def resolve(self, needed: dict, refs: dict, fetch) -> list:
        """Where this node reads each needed file {path: [group, size, mtime_ns]}; fetches shipped ones into the
        cache (fetch: ray.get, of refs {path: ObjectRef of its bytes}). Returns the paths still to be shipped (not
        cached here and not in refs)."""
        missing = []
        for path, (group, size, mtime) in needed.items():
            if self.where.get(path, (None,))[1:] == (size, mtime):
                continue
            if self.decide(group, path, [size, mtime]) == "seen":
                if fingerprint(Path(path)) != [size, mtime]:
                    raise InputError(f"--ray: node {self._name()} sees {path} but not the driver's copy of it (a "
                                     "stale copy? --ray-files ship sends the files)")
                self.where[path] = (path, size, mtime)
                continue
            cached = self.cache / path.lstrip("/")
            if fingerprint(cached) != [size, mtime]:
                if path not in refs:
                    missing.append(path)
                    continue
                write_bytes(cached, fetch(refs[path]))
                os.utime(cached, ns=(mtime, mtime))
            self.where[path] = (str(cached), size, mtime)
        return missing

    def node_path(self, path: str | None, group: str) -> str | None:
        """A driver path that is the root of `group`, as this node reads it."""
        if not path or not os.path.isabs(path) or self.groups.get(group) != "shipped":
            return path
        return str(self.cache / path.lstrip("/"))

    def node_spec(self, spec):
        """A side's SourceSpec (the driver's absolute paths) with its paths as this node reads them."""
        package_group = f"dir:{spec.package}" if f"dir:{spec.package}" in self.groups else f"file:{spec.package}"
        return replace(spec, package=self.node_path(spec.package, package_group),
                       textures=self.node_path(spec.textures, f"catalog:{spec.textures}"),
                       accessories=self.node_path(spec.accessories, f"catalog:{spec.accessories}"),
                       model=self.node_path(spec.model, f"file:{spec.model}"))

    def node_job(self, job: dict) -> dict:
        """The job with the files it names as this node reads them."""
        job = self._node_paths(dict(job), ("pose", "lights", "camera"))
        if "bodies" in job:
            job["bodies"] = [self._node_paths(dict(item), ("pose",)) for item in job["bodies"]]
        bg = job.get("background")
        if isinstance(bg, dict) and bg.get("folder"):
            folder = absolute(bg["folder"])
            job["background"] = {**bg, "folder": self.node_path(folder, f"dir:{folder}")}
        return job

    def _node_paths(self, fields: dict, keys: tuple) -> dict:
        """`fields` with the files at `keys` as this node reads them."""
        for key in keys:
            value = fields.get(key)
            if isinstance(value, str) and value in self.where:
                fields[key] = self.where[value][0]
        return fields
