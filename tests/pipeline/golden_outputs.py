"""What users see, fingerprinted: a fixed set of CLI commands run on the small build (tests/robustness/
probe_fixtures.py: packages, a dataset of each source kind, its FreiHAND and WebDataset layouts, single renders,
jobs files), every file they write hashed. A restructuring of the code must leave every hash as it was.

    python tests/pipeline/golden_outputs.py WORKDIR > tests/pipeline/golden_outputs.json   (from the reference commit)

The run happens in a process of its own whose numerics do not depend on the machine's CPU (REFERENCE_CPU): numpy's
ufuncs (exp, arctan2, ...) and OpenBLAS choose their kernels by the CPU's features, and an AVX-512 machine's last
bits differ from an AVX2 machine's (55 of the 168 hashes, from the fixture model's QR and exp on). The script starts
itself again with those settings when they are not set.

Files are hashed with the fixture, output and checkout folders' paths replaced by '<fx>', '<out>' and '<repo>' (labels
and records name their inputs by path) and,
for JSON documents, without their wall-clock fields (`timings`, `seconds`, `wall_s`...): what the run measured, not
what it made. Nor the texture stage's code digests (the bake's `key`, each catalogue entry's `fingerprint`): they hash
the stage's own source files (textures/bake.BAKE_MODULES, textures/build.RENDER_MODULES) so that any edit of them
re-renders the catalogue, as the Makefile does for any edit of the stage; the pixels they key are compared. Nothing
else is normalised.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import subprocess
import sys
import tarfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent), str(HERE.parent / "robustness"), str(HERE.parent / "model")]

# Keys of JSON documents whose values are measurements of the run (times, memory, process ids), not its output.
VOLATILE = {"timings", "seconds", "wall_s", "cpu_s", "elapsed_s", "ms", "cpu_ms", "end", "pid", "maxrss_mb",
            "open_s", "steps", "runner", "created", "date"}


# The CPU features the reference numbers are made with, whatever machine runs them: numpy's dispatch without its
# AVX-512 targets (the wheel's dispatch list, so the same names on every x86-64 machine) and OpenBLAS's Haswell
# kernels (AVX2). Read by numpy and OpenBLAS when they load: set before the process starts.
REFERENCE_CPU = {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR", "OPENBLAS_CORETYPE": "Haswell"}


def reference_run(workdir: Path) -> dict:
    """run_all(workdir/fx, workdir/out) in a new process with REFERENCE_CPU: {name: sha256}."""
    done = subprocess.run([sys.executable, __file__, str(workdir)], env={**os.environ, **REFERENCE_CPU},
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"golden_outputs.py {workdir} exited {done.returncode}: {done.stderr[-2000:]}")
    return json.loads(done.stdout)


def commands(fx: Path, out: Path) -> list[list[str]]:
    """The CLI commands (argv after `darthand`) whose outputs are fingerprinted, each writing under `out`."""
    model, tex, acc = str(fx / "model" / "right.npz"), str(fx / "tex"), str(fx / "acc")
    usd = str(fx / "usd" / "right")
    common = ["--size", "64", "--processes", "1"]
    return [
        ["render-dataset", model, "--textures", tex, "--accessories", acc, "--count", "10", "--seed", "5",
         "--accessory-share", "0.5", "--out", str(out / "ds_model"), *common, "--formats", "freihand,webdataset",
         "--allow-non-mano"],
        ["render-dataset", model, "--textures", tex, "--accessories", acc, "--count", "4", "--seed", "2",
         "--sides", "left", "--shapes", "none", "--lights", "default", "--backgrounds", "none",
         "--out", str(out / "ds_left"), *common],
        ["render-dataset", usd, "--count", "4", "--seed", "3", "--sides", "right", "--out", str(out / "ds_usd"),
         *common],
        ["render-dataset", model, "--textures", tex, "--accessories", acc, "--count", "6", "--seed", "9",
         "--plan", str(out / "plan" / "jobs.json"), "--out", str(out / "plan")],
        ["render", model, "--textures", tex, "--accessories", acc, "--pose", "fist", "--texture",
         "light_tattoos_07", "--accessory", "ring_01_court_gold", "--size", "64", "--out", str(out / "r_model")],
        ["render", usd, "--pose", "ok", "--size", "64", "--depth", "--out", str(out / "r_usd")],
        ["dataset", "export", str(out / "ds_left"), "--format", "freihand", "--out", str(out / "ds_left_fh"),
         "--allow-non-mano"],
    ]


def run_all(fx: Path, out: Path) -> dict:
    """{'fx/...' or 'out/...': sha256} of the small build in `fx` (built there if it is not) and of every command's
    outputs, written under `out` (a new folder)."""
    from darthand.cli import main
    from probe_fixtures import build_fixtures

    fx, out = build_fixtures(Path(fx).resolve()), Path(out).resolve()
    for argv in commands(fx, out):
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()) as err:
            code = main(argv)
        if code != 0:
            raise RuntimeError(f"darthand {' '.join(argv)} exited {code}: {err.getvalue()}")
    markers = {str(fx).encode(): b"<fx>", str(out).encode(): b"<out>", str(_checkout()).encode(): b"<repo>"}
    return {**fingerprints(fx, "fx", markers), **fingerprints(out, "out", markers)}


def _checkout() -> Path:
    """The checkout whose code runs (models record the template they were built from by its path)."""
    import darthand

    return Path(darthand.__file__).resolve().parents[2]


def fingerprints(root: Path, prefix: str, markers: dict) -> dict:
    """{prefix/relative path: sha256} of the files under root, each with the `markers` replaced (bytes -> bytes)."""
    result = {}
    for path in sorted(p for p in Path(root).rglob("*") if p.is_file()):
        rel = f"{prefix}/{path.relative_to(root).as_posix()}"
        if rel.endswith((".lock", "fixtures-ok")):
            continue
        if path.suffix == ".tar":
            data = _member_hashes(path, markers)
        elif path.suffix == ".npz":
            data = _array_hashes(path, markers)
        else:
            data = _normalised(path.name, path.read_bytes(), markers)
        result[rel] = hashlib.sha256(data).hexdigest()
    return result


def _normalised(name: str, data: bytes, markers: dict) -> bytes:
    for marker, replacement in markers.items():
        data = data.replace(marker, replacement)
    return _stable_json(data) if name.endswith(".json") else data


def _array_hashes(path: Path, markers: dict) -> bytes:
    """An .npz by its arrays (names, dtypes, shapes, bytes; text arrays with the markers replaced): compressed
    members hide the paths the replacement must find."""
    lines = []
    with np.load(path, allow_pickle=False) as npz:
        for name in sorted(npz.files):
            if path.name.startswith("bake_") and name == "key":        # a code digest (module docstring)
                continue
            array = npz[name]
            data = array.tobytes()
            if array.dtype.kind == "U":                                  # text: as UTF-8, where the paths are
                data = _normalised(name, "\n".join(array.ravel().tolist()).encode(), markers)
            elif array.dtype.kind in "SV" or name.endswith("_json"):
                data = _normalised(name, data, markers)
            dtype = "text" if array.dtype.kind == "U" else array.dtype.str     # a text's length follows its paths
            lines.append(f"{name} {dtype} {array.shape} {hashlib.sha256(data).hexdigest()}")
    return "\n".join(lines).encode()


def _member_hashes(path: Path, markers: dict) -> bytes:
    """A tar file by its members (names, modes, times and normalised contents, in order): its headers record
    sizes, which the path replacement would otherwise leave differing."""
    lines = []
    with tarfile.open(path) as tar:
        for member in tar.getmembers():
            data = tar.extractfile(member).read() if member.isfile() else b""
            digest = hashlib.sha256(_normalised(member.name, data, markers)).hexdigest()
            lines.append(f"{member.name} {member.mode:o} {member.mtime} {member.uid} {member.gid} {digest}")
    return "\n".join(lines).encode()


def _stable_json(data: bytes) -> bytes:
    try:
        doc = json.loads(data)
    except ValueError:
        return data
    if isinstance(doc, dict) and doc.get("format") == "darthand-texture-catalog":
        doc["bake"].pop("key", None)
        for entry in doc.get("entries", []):
            entry.pop("fingerprint", None)
    return json.dumps(_drop_volatile(doc), sort_keys=True).encode()


def _drop_volatile(value):
    if isinstance(value, dict):
        return {k: _drop_volatile(v) for k, v in value.items() if k not in VOLATILE}
    if isinstance(value, list):
        return [_drop_volatile(v) for v in value]
    return value


if __name__ == "__main__":
    if any(os.environ.get(k) != v for k, v in REFERENCE_CPU.items()):
        os.execve(sys.executable, [sys.executable, *sys.argv], {**os.environ, **REFERENCE_CPU})
    print(json.dumps(run_all(Path(sys.argv[1]) / "fx", Path(sys.argv[1]) / "out"), indent=1, sort_keys=True))
