"""Objects held in the studio (studio/objects.py): a small build (studio_build.py) with the toy object catalogue
(tests/render/object_catalog.py: trimesh's sphere) and its grasps fitted by the grasps stage. Checked against
independent truth: the served mesh lies on the sphere of known radius; the refitted grasp's hand, posed by
darthand's forward pass from the served joint angles, touches that sphere at the served placement without passing
into it; the exported jobs file renders through `darthand render-dataset` to the studio's own Render; the page picks
an object and a grasp in a real browser without console errors."""

from __future__ import annotations

import base64
import http.client
import json
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "render"))

from object_catalog import SPHERE_RADIUS, toy_items, write_catalog  # noqa: E402
from studio_build import make_build  # noqa: E402

from darthand.errors import InputError  # noqa: E402
from testkit.browser import BrowserUnavailable, StudioProcess, chromium, drive  # noqa: E402

BALL = "ball_01"


@pytest.fixture(scope="module")
def build(tmp_path_factory) -> Path:
    """The studio's test build with objects/ (the toy ball) and grasps/ (its grasps on the right hand)."""
    from darthand.grasps.build import build_grasps

    root = make_build(tmp_path_factory.mktemp("studio_objects"))
    ball = [i for i in toy_items() if i.id == BALL]
    write_catalog(root / "objects", ball)
    build_grasps(ball, {"right": str(root / "model" / "right.npz")}, root / "grasps", sheet=False, approaches=1)
    return root


@pytest.fixture(scope="module")
def server(build):
    from darthand.studio.build import StudioBuild
    from darthand.studio.server import Studio, make_server

    srv = make_server(Studio(StudioBuild(build)))
    thread = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    yield srv
    srv.shutdown()
    srv.server_close()


def call(srv, method: str, path: str, body=None):
    """(status, JSON or raw bytes) of one request."""
    host, port = srv.server_address[:2]
    conn = http.client.HTTPConnection(host, port, timeout=600)
    headers = {"Host": f"{host}:{port}"}
    data = None if body is None else json.dumps(body).encode()
    if data is not None:
        headers["Content-Type"] = "application/json"
    conn.request(method, path, body=data, headers=headers)
    reply = conn.getresponse()
    raw = reply.read()
    conn.close()
    kind = reply.getheader("Content-Type") or ""
    return reply.status, (json.loads(raw) if kind.startswith("application/json") else raw)


def first_grasp(srv) -> dict:
    status, listing = call(srv, "GET", "/api/objects")
    assert status == 200
    return listing["objects"][0]["grasps"]["right"][0]


def test_listing_mesh_and_thumbnail(server):
    status, catalogue = call(server, "GET", "/api/catalogue")
    assert status == 200 and catalogue["objects"] is True
    status, listing = call(server, "GET", "/api/objects")
    assert status == 200 and listing["categories"] == ["ball"]
    (ball,) = listing["objects"]
    assert ball["id"] == BALL and set(ball["grasps"]) == {"right"}            # grasps fitted on the right hand only
    assert all(g["id"].startswith(f"{BALL}/{g['type']}/") for g in ball["grasps"]["right"])
    status, mesh = call(server, "GET", f"/api/object/{BALL}")
    assert status == 200
    for part in mesh["parts"]:
        v = np.asarray(part["positions"]).reshape(-1, 3)
        n = np.asarray(part["normals"]).reshape(-1, 3)
        assert np.allclose(np.linalg.norm(v, axis=1), SPHERE_RADIUS, atol=1e-4)   # trimesh's sphere, centred
        assert np.einsum("ij,ij->i", n, v / SPHERE_RADIUS).min() > 0.99          # outward normals
        assert max(part["indices"]) < len(v)
    status, png = call(server, "GET", f"/media/object/{BALL}.png")
    assert status == 200 and png[:8] == b"\x89PNG\r\n\x1a\n"


def test_unknown_objects_and_grasps_are_404(server):
    grasp = first_grasp(server)
    assert call(server, "GET", "/api/object/no_such")[0] == 404
    assert call(server, "GET", "/media/object/no_such.png")[0] == 404
    status, reply = call(server, "POST", "/api/grasp", {"side": "right", "object": BALL, "grasp": "ball_01/x/0"})
    assert status == 404 and "grasp 'ball_01/x/0'" in reply["error"]
    status, reply = call(server, "POST", "/api/grasp", {"side": "left", "object": BALL, "grasp": grasp["id"]})
    assert status == 404 and "left grasp" in reply["error"]
    scene = {"side": "right", "angles_deg": [[0, 0, 0]] * 16, "object": {"id": "no_such", "grasp": grasp["id"]}}
    assert call(server, "POST", "/api/render", scene)[0] == 404


def test_refitted_grasp_touches_the_sphere_without_passing_into_it(server, build):
    from darthand.model.anatomy import angles_to_axis_angle
    from darthand.model.forward import forward
    from darthand.model.npz_io import load_npz

    grasp = first_grasp(server)
    status, doc = call(server, "POST", "/api/grasp", {"side": "right", "object": BALL, "grasp": grasp["id"]})
    assert status == 200 and doc["type"] == grasp["type"]
    model = load_npz(build / "model" / "right.npz")
    pose = angles_to_axis_angle(model, np.deg2rad(np.asarray(doc["angles_deg"])))
    vertices = forward(model, pose.reshape(1, 48)).vertices[0]
    P = np.asarray(doc["placement"])
    assert np.allclose(P[:3, :3] @ P[:3, :3].T, np.eye(3), atol=1e-6) and np.allclose(P[3], [0, 0, 0, 1])
    distance = np.linalg.norm(vertices - P[:3, 3], axis=1) - SPHERE_RADIUS   # the centre's image
    assert -distance.min() <= 2.5e-3                       # no vertex deeper than the catalogue's 2 mm (+ facets)
    assert (np.abs(distance) < 3e-3).sum() >= 20          # the hand touches the ball
    assert doc["penetration_max_mm"] <= 2.0 + 1e-9


def test_the_object_turns_with_the_wrist_in_the_export(server, build):
    """Wrist sliders moved after a grasp is picked: the exported job's object keeps the grip. Truth: the hand posed
    by darthand's forward pass from the job's pose keeps every vertex's distance to the ball's centre (the centre
    taken from the job's placement) within 1e-6 m of the grasp's own, while the wrist edit moves the fingers by
    centimetres."""
    from darthand.model.forward import forward
    from darthand.model.npz_io import load_npz

    grasp = first_grasp(server)
    status, doc = call(server, "POST", "/api/grasp", {"side": "right", "object": BALL, "grasp": grasp["id"]})
    model = load_npz(build / "model" / "right.npz")

    def exported(angles):
        scene = {"side": "right", "angles_deg": angles, "object": {"id": BALL, "grasp": grasp["id"]}, "name": "w"}
        status, reply = call(server, "POST", "/api/export/scene", scene)
        assert status == 200, reply
        frame = reply["document"]["frames"][0]
        vertices = forward(model, np.asarray(frame["bodies"][0]["pose"]).reshape(1, 48)).vertices[0]
        return vertices, np.asarray(frame["bodies"][1]["placement"])[:3, 3]

    turned = np.asarray(doc["angles_deg"])
    turned[0] += [20.0, -15.0, 30.0]                                    # the wrist: twist, spread, bend
    v0, c0 = exported(doc["angles_deg"])
    v1, c1 = exported(turned.tolist())
    assert np.linalg.norm(v1 - v0, axis=1).max() > 0.02
    d0, d1 = (np.linalg.norm(v - c, axis=1) for v, c in ((v0, c0), (v1, c1)))
    assert np.abs(d1 - d0).max() < 1e-6


def test_an_export_with_the_hand_through_its_object_is_refused(server):
    """The page's fingers bent 40 degrees further than the grasp's close through the ball: the export is refused as
    render-dataset --jobs would refuse the file (dataset/jobs.validate_jobs), in one line."""
    grasp = first_grasp(server)
    status, doc = call(server, "POST", "/api/grasp", {"side": "right", "object": BALL, "grasp": grasp["id"]})
    angles = np.asarray(doc["angles_deg"])
    angles[1:13, 2] += 40.0                                      # index, middle, pinky, ring: bend
    scene = {"side": "right", "angles_deg": angles.tolist(), "object": {"id": BALL, "grasp": grasp["id"]},
             "name": "through"}
    status, reply = call(server, "POST", "/api/export/scene", scene)
    assert status == 422 and "passes into object 'ball_01'" in reply["error"] and "\n" not in reply["error"]


def test_views_frame_the_hand_and_its_object(server):
    grasp = first_grasp(server)
    status, doc = call(server, "POST", "/api/grasp", {"side": "right", "object": BALL, "grasp": grasp["id"]})
    held = {"id": BALL, "grasp": grasp["id"]}
    for view in ("dorsal", "palmar", "radial", "ulnar", "three_quarter"):
        status, cam = call(server, "POST", "/api/camera", {"side": "right", "angles_deg": doc["angles_deg"],
                                                          "view": view, "size": 128, "object": held})
        assert status == 200, cam
        K, R, t = (np.asarray(cam[k]) for k in ("K", "R", "t"))
        centre = np.asarray(doc["placement"])[:3, 3]
        rim = centre + SPHERE_RADIUS * np.vstack([np.eye(3), -np.eye(3)])        # the ball's extreme points
        x = rim @ R.T + t
        uv = (x @ K.T)[:, :2] / x[:, 2:]
        assert (x[:, 2] > 0).all() and (uv >= 0).all() and (uv <= 128).all(), (view, uv)


def test_no_catalogues_hide_objects_and_named_ones_must_exist(tmp_path, build):
    from darthand.studio.objects import find_catalogs

    assert find_catalogs(tmp_path) is None
    assert find_catalogs(build) == (build / "objects" / "catalog.json", build / "grasps" / "catalog.json")
    with pytest.raises(InputError, match=r"^--grasps-catalog: no catalogue at .*nowhere"):
        find_catalogs(build, objects=build / "objects", grasps=tmp_path / "nowhere")


@pytest.mark.slow
def test_exported_object_scene_renders_as_the_studio_render_in_batch(server, build, tmp_path):
    from darthand.render.image import read_png

    grasp = first_grasp(server)
    status, doc = call(server, "POST", "/api/grasp", {"side": "right", "object": BALL, "grasp": grasp["id"]})
    status, camera = call(server, "POST", "/api/camera", {"side": "right", "angles_deg": doc["angles_deg"],
                                                         "view": "three_quarter", "size": 96})
    assert status == 200
    scene = {"side": "right", "angles_deg": doc["angles_deg"], "object": {"id": BALL, "grasp": grasp["id"]},
             "camera": {k: camera[k] for k in ("width", "height", "K", "R", "t")}, "name": "held"}
    status, exported = call(server, "POST", "/api/export/scene", scene)
    assert status == 200, exported
    frame = exported["document"]["frames"][0]
    assert [b["kind"] for b in frame["bodies"]] == ["hand", "object"] and "side" not in frame
    assert frame["bodies"][1] == {"kind": "object", "object": BALL, "placement": doc["placement"]}
    assert frame["grasp"]["id"] == grasp["id"] and frame["grasp"]["type"] == grasp["type"]
    status, render = call(server, "POST", "/api/render", {k: v for k, v in scene.items() if k != "name"})
    assert status == 200, render
    command = exported["document"]["studio"]["command"]
    assert f"--objects-catalog {build / 'objects' / 'catalog.json'}" in command
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "darthand.cli", "render-dataset", str(build / "model" / "right.npz"),
                           "--jobs", exported["path"], "--size", "96", "--arm", "off", "--out", str(out),
                           "--processes", "1"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    batch = read_png(next((out / "images").glob("*.png"))).astype(np.int64)
    studio = _png(render["image"]).astype(np.int64)
    assert batch.shape == studio.shape and np.abs(batch - studio).max() <= 1
    mask = _png(render["mask"])
    assert mask.any()


def _png(data: str) -> np.ndarray:
    from darthand.render.image import read_png

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "x.png"
        path.write_bytes(base64.b64decode(data))
        return read_png(path)


@pytest.mark.slow
def test_the_page_picks_an_object_and_a_grasp(build):
    """In a real browser: the object panel lists the ball, clicking it holds it in its first grasp (the hand posed
    by the grasp's angles, the object in the live view), the grasp list switches grasps, 'none' empties the hand."""
    try:
        chromium()
    except BrowserUnavailable as e:
        pytest.skip(str(e))
    steps = [
        {"do": "load"},
        {"do": "eval", "expr": "new Promise((r) => { const t = () => window.studio.objects() ? r(true) : "
                               "setTimeout(t, 50); t(); })"},
        {"do": "click", "selector": f"#objects figure[data-id='{BALL}']"},                                 # 2
        {"do": "eval", "expr": "window.studio.idle().then(() => ({object: window.studio.state.object, "
                               "angles: window.studio.state.angles, scene: window.studio.sceneDoc()}))"},
        {"do": "screenshot", "path": "/tmp/studio-object-page.png"},                                      # 4
        {"do": "screenshot", "selector": "#view", "path": "/tmp/studio-object-view.png"},
        {"do": "eval", "expr": "(() => { const s = document.getElementById('obj-grasp'); s.value = s.options[1].value; "
                               "s.dispatchEvent(new Event('change')); return s.value; })()"},    # 6
        {"do": "eval", "expr": "window.studio.idle().then(() => ({object: window.studio.state.object, "
                               "angles: window.studio.state.angles}))"},
        {"do": "eval", "expr": "(() => { for (const [a, v] of [[0, 20], [1, -15], [2, 30]]) {"       # 8: the wrist
                               " const s = document.getElementById(`slider-0-${a}`); s.value = +s.value + v;"
                               " s.dispatchEvent(new Event('input')); s.dispatchEvent(new Event('change')); }"
                               " window.studio.state.renderSize = 128; return window.studio.state.angles; })()"},
        {"do": "click", "selector": "#render"},
        {"do": "eval", "expr": "(({mask, image, size, job}) => ({mask, image, size, job,"
                               " live: window.studio.silhouette(size)}))(window.studio.state.lastRender)"},   # 10
        {"do": "eval", "expr": "(window.heldScene = window.studio.sceneDoc(), true)"},
        {"do": "click", "selector": "#objects figure[data-id='none']"},                                  # 12
        {"do": "eval", "expr": "({object: window.studio.state.object, angles: window.studio.state.angles, "
                               "errors: window.studio.errors})"},
        {"do": "eval", "expr": "window.studio.loadScene(window.heldScene).then(() => window.studio.idle())"
                               ".then(() => ({object: window.studio.state.object, angles: window.studio.state.angles,"
                               " shown: document.querySelector('#objects figure.selected').dataset.id}))"},  # 14
        {"do": "screenshot", "path": "/tmp/studio-object-render.png"},
    ]
    with StudioProcess(build) as studio:
        report = drive(studio.url, steps)
    assert "error" not in report, report.get("error")
    held = report["results"][3]
    assert held["object"]["id"] == BALL and held["scene"]["object"] == held["object"]
    assert np.abs(np.asarray(held["angles"])).max() > 5                     # the grasp's pose, not the flat hand
    other = report["results"][7]
    assert other["object"] == {"id": BALL, "grasp": report["results"][6]} != held["object"]
    assert np.abs(np.asarray(other["angles"]) - np.asarray(held["angles"])).max() > 1   # another grasp's pose
    rendered = report["results"][10]
    assert [b["kind"] for b in rendered["job"]["bodies"]] == ["hand", "object"]
    size = rendered["size"]
    hand = _png(rendered["mask"])
    hand = (hand[..., 0] if hand.ndim == 3 else hand) > 127               # the hand's mask: the object is not in it
    drawn = _png(rendered["image"])[..., 3] > 127                           # the image's alpha: hand and object
    live = np.frombuffer(base64.b64decode(rendered["live"]), np.uint8).reshape(size, size).astype(bool)
    iou = (drawn & live).sum() / (drawn | live).sum()
    assert iou >= 0.97, f"the render's alpha and the live view's silhouette (hand and object, the wrist turned " \
        f"after the grasp: the object follows it in both): IoU {iou:.4f}"
    assert (drawn & ~hand).sum() > 0.02 * drawn.sum() and (hand & ~drawn).sum() <= 0.005 * hand.sum()
    empty = report["results"][13]
    assert empty["object"] is None and np.abs(np.asarray(empty["angles"])).max() == 0
    loaded = report["results"][14]                                  # a saved scene brings its object and grasp back
    assert loaded["object"] == other["object"] and loaded["shown"] == BALL
    assert np.allclose(loaded["angles"], report["results"][8])
    assert not report["console"] and not report["page_errors"] and not report["failed_requests"], report
