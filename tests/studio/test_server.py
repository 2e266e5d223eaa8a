"""The studio server refuses bad requests with one-line 4xx errors and never reads outside the build: unknown ids,
path traversal (raw, percent-encoded, through three.js's folder), oversized or non-JSON bodies, NaN, a foreign Host
header, methods it does not serve; and the `darthand studio` command's own argument errors."""

from __future__ import annotations

import http.client
import json
import sys
import threading
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from studio_build import RING, make_build  # noqa: E402

ZERO = [[0.0, 0.0, 0.0]] * 16


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from darthand.studio.build import StudioBuild
    from darthand.studio.server import Studio, make_server

    build = make_build(tmp_path_factory.mktemp("studio_build"))
    (build.parent / "secret.txt").write_text("outside the build")
    srv = make_server(Studio(StudioBuild(build)))
    thread = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    yield srv, build
    srv.shutdown()
    srv.server_close()


def request(server, method, path, body=None, headers=None):
    """(status, parsed JSON or raw bytes) of a raw request (the path is sent as written: no client normalisation)."""
    srv, _ = server
    host, port = srv.server_address[:2]
    conn = http.client.HTTPConnection(host, port, timeout=30)
    hdrs = {"Host": f"{host}:{port}", **(headers or {})}
    data = body if isinstance(body, bytes) or body is None else json.dumps(body).encode()
    if data is not None and "Content-Type" not in hdrs:
        hdrs["Content-Type"] = "application/json"
    conn.putrequest(method, path, skip_host=True, skip_accept_encoding=True)
    for k, v in hdrs.items():
        conn.putheader(k, v)
    if data is not None and "Content-Length" not in hdrs:
        conn.putheader("Content-Length", str(len(data)))
    conn.endheaders()
    if data is not None:
        try:
            conn.send(data)
        except (BrokenPipeError, ConnectionResetError):    # refused before the body was read: the reply is there
            pass
    r = conn.getresponse()
    raw = r.read()
    conn.close()
    if r.getheader("Content-Type", "").startswith("application/json"):
        return r.status, json.loads(raw)
    return r.status, raw


def refused(server, method, path, body=None, headers=None) -> tuple[int, str]:
    """(status, message) of a request the server must refuse with a one-line JSON error."""
    status, doc = request(server, method, path, body, headers)
    assert isinstance(doc, dict) and set(doc) == {"error", "status"}, doc
    assert 400 <= status < 500 and doc["status"] == status
    assert "\n" not in doc["error"] and "Traceback" not in doc["error"]
    return status, doc["error"]


def test_serves_the_page_catalogue_rig_and_package(server):
    status, page = request(server, "GET", "/")
    assert status == 200 and b"studio.js" in page
    status, cat = request(server, "GET", "/api/catalogue")
    assert status == 200 and cat["sides"] == ["right", "left"] and RING in [a["id"] for a in cat["accessories"]]
    status, rig = request(server, "GET", "/api/rig/left")
    assert status == 200 and len(rig["joint_frames"]) == 16 and "fist" in rig["gestures"]
    status, gltf = request(server, "GET", "/gltf/right/right.gltf")
    assert status == 200 and json.loads(gltf)["asset"]["version"] == "2.0"
    assert request(server, "GET", "/vendor/three/build/three.module.js")[0] == 200


@pytest.mark.parametrize("path", [
    "/gltf/right/../../secret.txt", "/gltf/right/..%2f..%2fsecret.txt", "/gltf/right/%2e%2e/%2e%2e/secret.txt",
    "/static/../server.py", "/static/..%2fserver.py", "/vendor/three/../../package.json",
    "/vendor/three/build/..%2f..%2f..%2fpackage.json", "/gltf/right/%5c..%5csecret.txt",
])
def test_path_traversal_is_refused(server, path):
    status, message = refused(server, "GET", path)
    assert status in (400, 404)


@pytest.mark.parametrize("path,status", [
    ("/gltf/right/right.npz", 404),                    # a file in the folder the .gltf does not list
    ("/gltf/middle/middle.gltf", 404),                 # no such side
    ("/vendor/three/package.json", 404),               # three.js's own files outside build/ and examples/jsm/
    ("/vendor/other/x.js", 404),
    ("/media/texture/right/no_such_texture.png", 404),
    ("/media/accessory/right/watch_99_nope.png", 404),
    ("/media/accessory/right/none.glb", 404),
    ("/media/background/builtin/99999.png", 404),
    ("/media/background/image/0.png", 404),            # no --backgrounds folder given
    ("/api/rig/up", 404),
    ("/api/nothing", 404),
    ("/nowhere", 404),
])
def test_unknown_names_are_404(server, path, status):
    assert refused(server, "GET", path)[0] == status


def scene(**kw):
    return {"side": "right", "angles_deg": ZERO, **kw}


@pytest.mark.parametrize("body,status,words", [
    (scene(texture="../../secret"), 404, "texture"),
    (scene(texture="gold_skin_99"), 404, "texture"),
    (scene(accessory="watch_99_nope"), 404, "accessory"),
    (scene(side="middle"), 400, "side"),
    ({"angles_deg": ZERO}, 400, "side"),
    (scene(angles_deg=[[0, 0, 0]] * 15), 400, "angles_deg"),
    (scene(angles_deg=[[0, 0, 500]] + [[0, 0, 0]] * 15), 400, "angles_deg"),
    (scene(background={"image": 0}), 404, "background"),
    (scene(background={"folder": "/etc", "files": ["passwd"]}), 400, "background"),
    (scene(camera={"width": 64, "height": 32, "K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                   "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "t": [0, 0, 1]}), 400, "camera"),
    (scene(camera={"width": 99999, "height": 99999, "K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                   "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "t": [0, 0, 1]}), 400, "camera"),
    (scene(lights={"ambient": {"intensity": -4}}), 400, "lights"),
    (scene(name="../../evil"), 400, "name"),
    ([1, 2, 3], 400, "scene"),
])
def test_bad_scenes_are_refused(server, body, status, words):
    for call in ("/api/render", "/api/export/scene", "/api/export/pose"):
        got, message = refused(server, "POST", call, body)
        assert got == status, (call, message)
        assert words in message, message


def test_bad_bodies_are_refused(server):
    assert refused(server, "POST", "/api/render", b"{" * 10)[0] == 400
    nan = b'{"side": "right", "angles_deg": [[NaN, 0, 0]]}'
    assert refused(server, "POST", "/api/render", nan)[0] == 400
    assert refused(server, "POST", "/api/render", json.dumps(scene()).encode(),
                   {"Content-Type": "text/plain"})[0] == 415
    assert refused(server, "POST", "/api/render", b"x" * (2 << 20))[0] == 413
    assert refused(server, "POST", "/api/render", b"{}", {"Content-Length": "99999999999"})[0] == 413
    assert refused(server, "POST", "/api/export/poses", {"poses": []})[0] == 400
    assert refused(server, "POST", "/api/export/poses", {"poses": [ZERO] * 10_001})[0] in (400, 413)
    assert refused(server, "POST", "/api/camera", {"side": "right", "angles_deg": ZERO, "view": "sky"})[0] == 404
    assert refused(server, "POST", "/api/camera", {"side": "right", "angles_deg": ZERO, "view": "three_quarter",
                                                   "size": 10 ** 6})[0] == 400


def test_foreign_host_and_methods_are_refused(server):
    assert refused(server, "GET", "/api/catalogue", headers={"Host": "evil.example:80"})[0] == 403
    assert refused(server, "PUT", "/api/render", scene())[0] == 405
    assert refused(server, "DELETE", "/gltf/right/right.gltf")[0] == 405


def test_exports_are_written_inside_the_build(server):
    _, build = server
    status, doc = request(server, "POST", "/api/export/scene", scene(texture="dark_tattoos_00", accessory=RING,
                                                                     background={"color": [0.2, 0.3, 0.4]},
                                                                     name="my_scene"))
    assert status == 200
    path = Path(doc["path"])
    assert path == build / "studio" / "scenes" / "my_scene.json" and path.is_file()
    from darthand.dataset.jobs import check_jobs

    check_jobs(json.loads(path.read_text()), "scene")


def test_cli_argument_errors_are_one_line(tmp_path, capsys):
    from darthand.cli import main

    for args in (["studio", str(tmp_path / "nothing")], ["studio", str(tmp_path)],
                 ["studio", str(tmp_path), "--host", "0.0.0.0"], ["studio", str(tmp_path), "--port", "70000"]):
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and err.startswith("darthand: error:"), err
