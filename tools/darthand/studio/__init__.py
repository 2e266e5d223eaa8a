"""The studio: a local authoring page over a build's glTF packages and the reference renderer (`darthand studio`).

build.py what a build folder offers the page (sides, packages, catalogue ids) and the checks of every id a request
names; rig.py the per-side data the page poses the glTF with; media.py thumbnails, accessory glTFs and backgrounds;
environments.py the environment maps offered (render/environment.py's built-in set and --environments DIR), their
thumbnails and live copies; request_error.py the refusal every module raises;
scene.py a scene from the page as a checked one-frame dataset job, pose files, exports and the render; server.py the
HTTP server (127.0.0.1, validated requests, bounded work); static/ the page (three.js from the repo's node_modules).
"""
