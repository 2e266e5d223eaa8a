"""The studio server refuses bad requests with one-line 4xx errors and never reads outside the build: unknown ids,
path traversal (raw, percent-encoded, through three.js's folder), oversized or non-JSON bodies, NaN, a foreign Host
header, methods it does not serve; and the `darthand studio` command's own argument errors."""

from __future__ import annotations

import base64
import http.client
import json
import sys
import threading
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from studio_build import RING, make_build, make_environments  # noqa: E402

ZERO = [[0.0, 0.0, 0.0]] * 16


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from darthand.studio.build import StudioBuild
    from darthand.studio.server import Studio, make_server

    build = make_build(tmp_path_factory.mktemp("studio_build"))
    (build.parent / "secret.txt").write_text("outside the build")
    environments = make_environments(build.parent / "environments")
    srv = make_server(Studio(StudioBuild(build, environments=environments)))
    thread = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    yield srv, build
    srv.shutdown()
    srv.server_close()


def request(server, method, path, body=None, headers=None, timeout=30):
    """(status, parsed JSON or raw bytes) of a raw request (the path is sent as written: no client normalisation)."""
    srv, _ = server
    host, port = srv.server_address[:2]
    conn = http.client.HTTPConnection(host, port, timeout=timeout)
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
    (scene(lights={"environment": {"map": "../../secret.txt"}}), 404, "environment"),
    (scene(lights={"environment": {"map": "broken.exr"}}), 422, "cannot read environment map"),
    (scene(lights={"environment": {"map": "uniform.hdr", "strength": -1}}), 400, "strength"),
    (scene(lights={"environment": {"map": "uniform.hdr", "frame": "sky"}}), 400, "frame"),
    (scene(background={"environment": {"blur": 2}}), 400, "environment"),
    (scene(lights={"environment": {"map": "uniform.hdr"}}, background={"environment": {"blur": 60}}), 400, "blur"),
    (scene(film=[1]), 400, "film"),
    (scene(film={"shutter_ms": 8}), 400, "'shutter_ms'"),
    (scene(film={"iso": 10}), 400, "iso"),
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


# ------------------------------------------------------------------------------------------------ environments


def _image(data: bytes) -> np.ndarray:
    """Pixels of PNG or Radiance .hdr bytes, decoded by Pillow (PNG) or OpenImageIO (.hdr): not the studio's code."""
    import io
    import tempfile

    if data[:4] == b"\x89PNG":
        from PIL import Image

        return np.asarray(Image.open(io.BytesIO(data)))
    import OpenImageIO as oiio

    with tempfile.NamedTemporaryFile(suffix=".hdr") as f:
        f.write(data)
        f.flush()
        return oiio.ImageBuf(f.name).get_pixels(oiio.FLOAT)


def listing(server) -> dict:
    status, doc = request(server, "GET", "/api/environments")
    assert status == 200
    return {e["id"]: e for e in doc["environments"]}


def test_environments_listing_marks_bad_maps_with_their_reason(server):
    maps = listing(server)
    assert maps["directions.hdr"] == {"id": "directions.hdr", "source": "folder", "usable": True}
    assert "notes.txt" not in maps
    assert not maps["broken.exr"]["usable"] and "cannot read environment map" in maps["broken.exr"]["reason"]
    assert not maps["wide.exr"]["usable"] and "48x16, not 2:1" in maps["wide.exr"]["reason"]
    builtin = [k for k, e in maps.items() if e["source"] == "builtin"]
    assert {"studio", "city", "forest", "sunset"} <= set(builtin)      # the vendored maps (render/environments)
    assert all(maps[k]["usable"] for k in builtin)
    assert list(maps)[:len(builtin)] == builtin            # built-ins first


def test_a_map_that_fails_to_decode_becomes_unusable_not_an_error(server):
    """nan.exr passes the header check; decoding it for its thumbnail finds the NaN: one-line 422, then listed
    unusable with that reason, and the listing itself still answers."""
    status, message = refused_any(server, "GET", "/media/environment/nan.exr.png")
    assert status == 422 and "NaN" in message
    maps = listing(server)
    assert not maps["nan.exr"]["usable"] and "NaN" in maps["nan.exr"]["reason"]
    assert maps["uniform.hdr"]["usable"]


def refused_any(server, method, path, body=None):
    """(status, message) of a one-line JSON refusal of any status (refused() takes 4xx only)."""
    status, doc = request(server, method, path, body)
    assert isinstance(doc, dict) and set(doc) == {"error", "status"} and doc["status"] == status, doc
    assert "\n" not in doc["error"]
    return status, doc["error"]


def test_thumbnails_are_small_tone_mapped_pngs(server):
    """Every usable map's thumbnail is a 128 x 64 PNG; a uniform map's is the closed form of the tone curve:
    exposed to 0.3 (its log-average), x / (1 + x) = 0.3 / 1.3 linear, sRGB-encoded."""
    for name, env in listing(server).items():
        if env["usable"] and name != "nan.exr":
            status, data = request(server, "GET", f"/media/environment/{quote(name)}.png")
            assert status == 200 and _image(data).shape == (64, 128, 3), name
    grey = _image(request(server, "GET", "/media/environment/uniform.hdr.png")[1]).astype(float)
    x = 0.3 / 1.3
    expected = 255 * (1.055 * x ** (1 / 2.4) - 0.055)
    assert np.abs(grey - expected).max() <= 1.0


def test_live_map_is_the_map_as_radiance_hdr(server):
    """The live view's .hdr decodes (OpenImageIO) to the folder's map, within RGBE's 8-bit mantissa shared by a
    texel's channels (1/256 of its largest channel, twice: the test wrote the map as RGBE too)."""
    from studio_build import direction_map

    status, data = request(server, "GET", "/media/environment/directions.hdr.hdr")
    assert status == 200 and data[:10] == b"#?RADIANCE"
    np.testing.assert_allclose(_image(data), direction_map(), rtol=0, atol=2 / 256)
    assert refused(server, "GET", "/media/environment/directions.hdr.exr")[0] == 404
    assert refused(server, "GET", "/media/environment/..%2f..%2fsecret.txt.hdr")[0] in (400, 404)
    assert refused(server, "GET", "/media/environment/wide.exr.png")[0] == 422


def test_scene_environment_reaches_the_job(server):
    """The exported job's lights carry the environment (a folder map by its path, a built-in by its name) and its
    background the dataset's environment backdrop ({'environment': true, 'blur'}, blur 0 too); the export keeps the
    studio scene (environment and film) to load back, and is a valid jobs file."""
    from darthand.dataset.jobs import check_jobs

    _, build = server
    env = {"map": "uniform.hdr", "rotation": 30.0, "strength": 1.5, "frame": "world"}
    body = scene(lights={"environment": env}, background={"environment": {"blur": 4.0}},
                 film={"exposure_ev": 0.5}, name="env_scene")
    status, doc = request(server, "POST", "/api/export/scene", body)
    assert status == 200, doc
    job = doc["document"]["frames"][0]
    assert job["lights"]["environment"] == {**env, "map": str(build.parent / "environments" / "uniform.hdr")}
    assert job["background"] == {"environment": True, "blur": 4.0}
    saved = doc["document"]["studio"]
    assert saved["scene"]["lights"]["environment"] == env and saved["film"] == {"exposure_ev": 0.5}
    check_jobs(doc["document"], "export")
    body = scene(lights={"environment": {"map": "studio"}}, background={"environment": {}})
    status, doc = request(server, "POST", "/api/export/scene", body)
    assert status == 200, doc
    job = doc["document"]["frames"][0]
    assert job["lights"]["environment"]["map"] == "studio" and job["background"] == {"environment": True, "blur": 0.0}
    check_jobs(doc["document"], "export")


def test_render_shows_a_uniform_environment_behind_the_hand(server):
    """Render under the uniform map (0.5 everywhere) at strength 1.5 with the environment backdrop, clean image:
    every pixel away from the hand is the closed form sRGB(0.75); the labels name the backdrop."""
    body = scene(lights={"environment": {"map": "uniform.hdr", "strength": 1.5, "frame": "world"}},
                 background={"environment": {"blur": 2.0}},
                 camera={"width": 64, "height": 64, "K": [[90, 0, 32], [0, 90, 32], [0, 0, 1]],
                         "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "t": [0, 0, 0.5]})
    status, doc = request(server, "POST", "/api/render", body, timeout=600)     # the first render compiles kernels
    assert status == 200, doc
    image, mask = (_image(base64.b64decode(doc[k])) for k in ("image", "mask"))
    mask = mask[..., 0] if mask.ndim == 3 else mask
    away = mask == 0
    assert 0 < (~away).sum() and away.sum() > 64 * 64 // 4
    x = 0.75
    expected = 255 * (1.055 * x ** (1 / 2.4) - 0.055)
    assert np.abs(image[..., :3][away].astype(float) - expected).max() <= 1.0
    assert doc["labels"]["render"]["background"]["used"] == "environment:uniform"


def test_the_jobs_string_backdrop_is_the_object_form_at_blur_0(server):
    """schemas/dataset_jobs.schema.json keeps the string 'environment' (`render --background environment`'s form) as
    the same backdrop as the studio's {'environment': true, 'blur': 0}: both are valid jobs and render the same
    bytes through the dataset's frame path."""
    from darthand.dataset.frames import render_job
    from darthand.dataset.jobs import check_jobs
    from darthand.render.api import Renderer, open_source

    _, build = server
    lights = {"environment": {"map": str(build.parent / "environments" / "directions.hdr"), "frame": "world"}}
    renderer = Renderer(open_source(build / "model" / "right.npz"))
    settings = {"size": 48, "samples": 4, "aa_shading": "triangle"}
    images = []
    for background in ("environment", {"environment": True, "blur": 0.0}):
        job = {"index": 0, "pose": None, "lights": lights, "background": background}
        check_jobs([job], "jobs")
        images.append(render_job(renderer, job, settings)[0].rgba)
    assert images[0][..., 3].min() == 255                  # the backdrop fills the frame
    np.testing.assert_array_equal(images[0], images[1])


def test_a_map_whose_pixels_are_bad_is_refused_for_a_scene_and_listed_unusable(server):
    """nan.exr's header is fine; a scene naming it decodes it (render/environment.read_map): one-line 422 naming
    the NaN, for export as for render, and the listing says so from then on."""
    body = scene(lights={"environment": {"map": "nan.exr"}})
    for call in ("/api/export/scene", "/api/render"):
        status, message = refused(server, "POST", call, body)
        assert status == 422 and "NaN" in message, (call, message)
    assert not listing(server)["nan.exr"]["usable"]


def test_environments_folder_that_is_not_one_is_one_line(server, tmp_path, capsys):
    from darthand.cli import main

    _, build = server
    assert main(["studio", str(build), "--environments", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--environments" in err and "not a folder" in err, err
