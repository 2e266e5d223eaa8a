"""The studio's HTTP server: the page, three.js, the build's glTF packages and media, and the JSON API.

Safety, since a browser on the same machine may be pointed at it by any web page:
- it listens on 127.0.0.1 unless told otherwise, and then answers only requests whose Host header names the address
  it listens on (no DNS rebinding);
- no request names a path: package files are those the .gltf lists, media and exports are named by catalogue ids
  or validated names, three.js files are looked up under node_modules/three only;
- POST bodies are JSON (Content-Type application/json, so a plain cross-site form cannot send one), at most
  MAX_BODY bytes, read with a socket timeout; every body is checked against its schema before anything runs;
- work per request is bounded: at most MAX_ACTIVE requests at once (503 beyond), one render per side at a time,
  images of at most 1024 pixels a side, pose lists of at most 10,000 poses.
Every refusal is a 4xx with {"error": one line}; an unexpected failure is a 500 with one line, logged once.
"""

from __future__ import annotations

import json
import mimetypes
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import unquote, urlsplit

import numpy as np

from darthand.dataset.backgrounds import BUILTIN_COUNT
from darthand.errors import InputError
from darthand.fileio import write_bytes
from darthand.model.preview import VIEWS
from darthand.render.camera import load_camera
from darthand.studio import media
from darthand.studio import scene as sc
from darthand.studio.build import RequestError, StudioBuild
from darthand.studio.rig import rig_document
from darthand.studio.scene import check_scene, scene_pose

STATIC = Path(__file__).resolve().parent / "static"
REPO_ROOT = Path(__file__).resolve().parents[3]
THREE_DIRS = ("build", "examples/jsm")          # what the page imports from the npm package `three`
MAX_BODY = 1 << 20
MAX_ACTIVE = 8
SOCKET_TIMEOUT = 30.0
JSON_TYPE = "application/json"


class Studio:
    """The server's state: the opened build, caches of what it made, and where three.js is."""

    def __init__(self, build: StudioBuild, three_root: Path | None = None):
        self.build = build
        self.three = (three_root or REPO_ROOT / "node_modules" / "three").resolve()
        if not (self.three / "build" / "three.module.js").is_file():
            raise InputError(f"{self.three}: three.js is not installed (run `make node` or `npm ci` in {REPO_ROOT})")
        self.static = {p.name: p for p in STATIC.iterdir() if p.is_file()}
        self.active = threading.BoundedSemaphore(MAX_ACTIVE)
        self._rigs: dict = {}
        self._packages: dict = {}
        self._made = threading.Lock()

    def rig(self, side: str) -> dict:
        if side not in self._rigs:
            self._rigs[side] = rig_document(self.build.side(side).model)
        return self._rigs[side]

    def package(self, side: str) -> dict:
        if side not in self._packages:
            self._packages[side] = json.loads(self.build.side(side).gltf.read_text())
        return self._packages[side]

    def three_file(self, rest: str) -> Path:
        """A file of the npm package three under one of THREE_DIRS (RequestError 404 otherwise)."""
        path = (self.three / rest).resolve()
        allowed = any(path.is_relative_to(self.three / d) for d in THREE_DIRS)
        if not allowed or path.suffix != ".js" or not path.is_file():
            raise RequestError(404, f"{rest!r} is not a three.js module the page uses")
        return path


def make_server(studio: Studio, host: str = "127.0.0.1", port: int = 0) -> ThreadingHTTPServer:
    """A bound (not yet serving) server; port 0 picks a free one (server.server_address[1])."""
    handler = type("StudioHandler", (StudioHandler,), {"studio": studio})
    try:
        server = ThreadingHTTPServer((host, port), handler)
    except OSError as e:
        raise InputError(f"studio: cannot listen on {host}:{port} ({e.strerror})") from None
    server.daemon_threads = True
    return server


class StudioHandler(BaseHTTPRequestHandler):
    studio: Studio
    server_version = "darthand-studio"
    protocol_version = "HTTP/1.1"
    timeout = SOCKET_TIMEOUT
    quiet = True

    # ---------------------------------------------------------------------------------------------- dispatch

    def do_GET(self):
        self._dispatch("GET")

    def do_POST(self):
        self._dispatch("POST")

    def do_PUT(self):
        self._refuse(405, "method PUT is not allowed")

    do_DELETE = do_PATCH = do_PUT

    def _dispatch(self, method: str) -> None:
        if not self.studio.active.acquire(blocking=False):
            return self._refuse(503, "the studio is busy: too many requests at once")
        try:
            self._check_host()
            parts = _path_parts(self.path)
            route: dict = GET_ROUTES if method == "GET" else POST_ROUTES
            key = parts[0] if parts else ""
            if key not in route:
                raise RequestError(404, f"no such {'page' if method == 'GET' else 'API call'}: {self.path[:100]!r}")
            if method == "POST":
                route[key](self, parts[1:], self._json_body())
            else:
                route[key](self, parts[1:])
        except RequestError as e:
            self._refuse(e.status, str(e))
        except InputError as e:
            self._refuse(400, str(e))
        except (BrokenPipeError, ConnectionResetError):
            pass
        except Exception as e:                     # a bug: one line in the log, one line to the page
            line = f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"
            print(f"[studio] internal error on {method} {self.path[:100]}: {line}", file=sys.stderr, flush=True)
            self._refuse(500, f"internal error: {line}")
        finally:
            self.studio.active.release()

    def _check_host(self) -> None:
        assert isinstance(self.server.server_address, tuple), "an IP server's address is (host, port, ...)"
        host, port = self.server.server_address[:2]
        given = (self.headers.get("Host") or "").strip().lower()
        allowed = {f"{host}:{port}", f"localhost:{port}"} if host in ("127.0.0.1", "localhost") else None
        if allowed is not None and given not in allowed:
            raise RequestError(403, f"Host {given!r} is not this studio's address")

    def _json_body(self):
        if (self.headers.get("Content-Type") or "").split(";")[0].strip().lower() != JSON_TYPE:
            raise RequestError(415, f"a POST body must be {JSON_TYPE}")
        length = self.headers.get("Content-Length")
        if length is None or not length.isdigit():
            raise RequestError(411, "a POST needs a Content-Length")
        if int(length) > MAX_BODY:
            self.close_connection = True
            raise RequestError(413, f"the body of {int(length)} bytes is over the limit of {MAX_BODY}")
        data = self.rfile.read(int(length))
        try:
            return json.loads(data, parse_constant=_no_constant)
        except (ValueError, UnicodeDecodeError) as e:
            raise RequestError(400, f"the body is not JSON ({str(e).splitlines()[0][:120]})") from None

    # ---------------------------------------------------------------------------------------------- replies

    def _send(self, status: int, body: bytes, content_type: str, cache: bool = False) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "max-age=3600" if cache else "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, doc, status: int = 200) -> None:
        self._send(status, json.dumps(doc, allow_nan=False).encode(), JSON_TYPE)

    def _file(self, path: Path, cache: bool = False) -> None:
        self._send(200, path.read_bytes(), _content_type(path), cache)

    def _refuse(self, status: int, message: str) -> None:
        try:
            self._json({"error": message, "status": status}, status)
        except (BrokenPipeError, ConnectionResetError):
            pass

    def log_message(self, format, *args):       # noqa: A002 (the base class's name)
        if not self.quiet:
            super().log_message(format, *args)

    # ---------------------------------------------------------------------------------------------- GET

    def get_page(self, rest):
        if rest:
            raise RequestError(404, f"no such page: {self.path[:100]!r}")
        self._file(self.studio.static["index.html"])

    def get_static(self, rest):
        if len(rest) != 1 or rest[0] not in self.studio.static:
            raise RequestError(404, f"no such static file: {'/'.join(rest)[:100]!r}")
        self._file(self.studio.static[rest[0]])

    def get_vendor(self, rest):
        if not rest or rest[0] != "three":
            raise RequestError(404, "only three.js is served under /vendor")
        self._file(self.studio.three_file("/".join(rest[1:])), cache=True)

    def get_api(self, rest):
        if rest == ["catalogue"]:
            return self._json(self.studio.build.catalogue())
        if rest == ["environments"]:
            return self._json({"environments": self.studio.build.environments.listing()})
        if len(rest) == 2 and rest[0] == "rig":
            return self._json(self.studio.rig(rest[1]))
        if rest == ["objects"]:
            return self._json(sc.held_objects(self.studio.build).listing())
        if len(rest) == 2 and rest[0] == "object":
            return self._json(sc.held_objects(self.studio.build).mesh(rest[1]))
        raise RequestError(404, f"no such API call: {self.path[:100]!r}")

    def get_gltf(self, rest):
        if len(rest) < 2:
            raise RequestError(404, "a package file is /gltf/<side>/<file>")
        side = self.studio.build.side(rest[0])
        self._file(self.studio.build.package_file(side, "/".join(rest[1:])), cache=True)

    def get_media(self, rest):
        build = self.studio.build
        cache = build.out_dir / "cache"
        if len(rest) == 3 and rest[0] == "background":
            kind, name = rest[1], _strip(rest[2], ".png")
            index = _index(name)
            if kind == "builtin":
                if index is None or index >= BUILTIN_COUNT:
                    raise RequestError(404, f"built-in background {name!r} is not in 0..{BUILTIN_COUNT - 1}")
                spec = {"builtin": index}
            elif kind == "image":
                path = build.background_file(index)
                spec = {"folder": str(path.parent), "files": [path.name], "builtin": 0}
            else:
                raise RequestError(404, f"no background kind {kind!r}")
            body = media.cached_file(cache / f"background_{kind}_{index}.png",
                                     lambda p: media.background_image(spec, p))
            return self._send(200, body, "image/png", cache=True)
        if len(rest) == 3 and rest[0] in ("texture", "accessory"):
            side = build.side(rest[1])
            name = rest[2]
            if rest[0] == "texture":
                tid = build.texture(side, _strip(name, ".png"))
                body = media.cached_file(cache / f"texture_{side.side}_{tid}.png",
                                         lambda p: media.texture_thumbnail(side, tid, p))
                return self._send(200, body, "image/png", cache=True)
            if name.endswith(".glb"):
                aid = build.accessory(side, _strip(name, ".glb"))
                if aid == "none":
                    raise RequestError(404, "accessory 'none' has no geometry")
                body = media.cached_file(cache / f"accessory_{side.side}_{aid}.glb",
                                         lambda p: _write(p, media.accessory_glb(side, aid, self.studio.package(
                                             side.side))))
                return self._send(200, body, "model/gltf-binary", cache=True)
            aid = build.accessory(side, _strip(name, ".png"))
            if aid == "none":
                raise RequestError(404, "accessory 'none' has no thumbnail")
            body = media.cached_file(cache / f"accessory_{side.side}_{aid}.png",
                                     lambda p: media.accessory_thumbnail(side, aid, p))
            return self._send(200, body, "image/png", cache=True)
        if len(rest) == 2 and rest[0] == "environment":
            return self._environment(rest[1], cache)
        if len(rest) == 2 and rest[0] == "object":
            held = sc.held_objects(build)
            object_id = held.item(_strip(rest[1], ".png")).id
            body = media.cached_file(cache / f"object_{object_id}.png", lambda p: held.thumbnail(object_id, p))
            return self._send(200, body, "image/png", cache=True)
        if len(rest) == 3 and rest[0] == "object" and rest[2] == "albedo.png":
            return self._file(sc.held_objects(build).albedo(rest[1]), cache=True)
        raise RequestError(404, f"no such media: {self.path[:100]!r}")

    def _environment(self, name: str, cache: Path) -> None:
        """An environment's thumbnail (<id>.png) or its map for the live view (<id>.hdr, RGBE)."""
        environments = self.studio.build.environments
        if name.endswith(".png"):
            return self._send(200, environments.thumbnail(name[:-4], cache), "image/png", cache=True)
        return self._send(200, environments.live_map(_strip(name, ".hdr"), cache), "image/vnd.radiance", cache=True)

    # ---------------------------------------------------------------------------------------------- POST

    def post_api(self, rest, body):
        build = self.studio.build
        if rest == ["render"]:
            return self._json(sc.render_scene(build, body))
        if rest == ["camera"]:
            return self._json(view_camera(build, body))
        if rest == ["grasp"]:
            return self._json(held_grasp(build, body))
        if rest == ["export", "pose"]:
            scene = sc.check_scene(build, body)
            name = sc.export_name(body, f"pose-{_stamp()}")
            doc = sc.pose_document(sc.scene_pose(build, scene))
            return self._json({"path": str(sc.write_export(build, "poses", name, doc)), "document": doc})
        if rest == ["export", "poses"]:
            poses = sc.check_pose_list(body)
            name = sc.export_name(body, f"poses-{_stamp()}")
            doc = sc.pose_document(sc.right_hand_poses(build, poses))
            return self._json({"path": str(sc.write_export(build, "pose_lists", name, doc)), "document": doc})
        if rest == ["export", "scene"]:
            scene = sc.check_scene(build, body)
            name = sc.export_name(body, f"scene-{_stamp()}")
            path = build.out_dir / "scenes" / f"{name}.json"
            doc = sc.scene_export(build, scene, str(path))
            return self._json({"path": str(sc.write_export(build, "scenes", name, doc)), "document": doc})
        raise RequestError(404, f"no such API call: {self.path[:100]!r}")


GET_ROUTES = {"": StudioHandler.get_page, "index.html": StudioHandler.get_page, "static": StudioHandler.get_static,
              "vendor": StudioHandler.get_vendor, "api": StudioHandler.get_api, "gltf": StudioHandler.get_gltf,
              "media": StudioHandler.get_media}
POST_ROUTES = {"api": StudioHandler.post_api}


def view_camera(build: StudioBuild, body) -> dict:
    """A named view framed on the posed hand and the object it holds (render/camera.py, as a job's view camera is
    framed on its bodies): {side, angles_deg, view, size, accessory?, object?} -> the camera's K, R, t, width,
    height and the point it frames."""
    if not isinstance(body, dict):
        raise RequestError(400, "camera: the body must be an object")
    view, size = body.get("view"), body.get("size", 512)
    if view not in VIEWS:
        raise RequestError(404, f"camera: view {view!r} is not one of {', '.join(VIEWS)}")
    if not isinstance(size, int) or isinstance(size, bool) or not 32 <= size <= 1024:
        raise RequestError(400, "camera: field 'size' must be an integer in 32..1024")
    scene = check_scene(build, {k: body[k] for k in ("side", "angles_deg", "accessory", "object") if k in body})
    side = build.side(scene["side"])
    with side.lock:
        subject = side.source.subject(scene_pose(build, scene), accessory=scene.get("accessory"))
    points = subject.all_vertices()
    if "object" in scene:
        points = np.concatenate([points, sc.held_objects(build).placed_vertices(side.side, scene["object"],
                                                                                scene_pose(build, scene))])
    cam = load_camera(view, points, width=size, height=size, side=side.side)
    centre = 0.5 * (points.min(0) + points.max(0))
    depth = float(cam.to_camera(centre[None])[0, 2])
    target = cam.centre + depth * cam.R[2]
    return {**cam.to_json(), "target": [float(x) for x in target]}


def held_grasp(build: StudioBuild, body) -> dict:
    """{side, object, grasp} -> the grasp refitted to the side's model (studio/objects.StudioObjects.grasp_document:
    joint angles in degrees, the object's placement in the hand's model frame)."""
    if not isinstance(body, dict) or not all(isinstance(body.get(k), str) for k in ("side", "object", "grasp")):
        raise RequestError(400, "grasp: the body must be {side, object, grasp} (strings)")
    side = build.side(body["side"]).side
    return sc.held_objects(build).grasp_document(side, body["object"], body["grasp"])


# ------------------------------------------------------------------------------------------------ helpers


def _path_parts(raw: str) -> list[str]:
    """The URL path's segments, decoded; RequestError 400 for a segment that could step outside ('..', '.', a
    decoded slash or backslash, a NUL)."""
    path = urlsplit(raw).path
    parts = [unquote(p) for p in path.split("/") if p]
    for p in parts:
        if p in (".", "..") or "/" in p or "\\" in p or "\x00" in p:
            raise RequestError(400, f"the path {path[:100]!r} is not allowed")
    return parts


def _strip(name: str, suffix: str) -> str:
    if not name.endswith(suffix):
        raise RequestError(404, f"{name!r} is not a {suffix} file")
    return name[:-len(suffix)]


def _index(text: str) -> int | None:
    return int(text) if text.isdigit() and len(text) < 9 else None


def _write(path: Path, data: bytes) -> None:
    write_bytes(path, data)


def _content_type(path: Path) -> str:
    kind = {".js": "text/javascript", ".mjs": "text/javascript", ".gltf": "model/gltf+json",
            ".bin": "application/octet-stream", ".css": "text/css", ".html": "text/html; charset=utf-8",
            ".png": "image/png", ".glb": "model/gltf-binary"}.get(path.suffix.lower())
    return kind or mimetypes.guess_type(path.name)[0] or "application/octet-stream"


def _no_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


def _stamp() -> str:
    return time.strftime("%Y%m%d-%H%M%S")
