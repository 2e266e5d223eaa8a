"""The `darthand manifest` and `darthand verify` commands: the build's own bookkeeping, which `make assets` runs on
every call (darthand/manifest.py does the work). Their options are defined in cli.py."""

from __future__ import annotations

from pathlib import Path

from darthand.manifest import check_manifest, invalidate, verify_outputs, write_manifest


def manifest(args) -> int:
    """Write BUILD/manifest.json (outputs, sha256, step times, checks), or with --check print the failed checks."""
    if args.check:
        return check_manifest(args.out or f"{args.build}/manifest.json")
    m = write_manifest(args.build, args.out)
    total = sum(e["bytes"] for e in m["outputs"])
    print(f"manifest: {len(m['outputs'])} outputs, {total / 1e6:.1f} MB, checks: {sorted(m['checks'])}"
          + (f", {len(m['failed_checks'])} failed" if m["failed_checks"] else ""))
    return 0


def verify(args) -> int:
    """Check every output against the manifest; exit 1 when one is damaged, or with --repair remove the damaged
    outputs and date their steps back so `make assets` rebuilds them (exit 0)."""
    if args.repair and not (Path(args.build) / "manifest.json").is_file():
        return 0
    damaged = verify_outputs(args.build, full=args.full)
    for rel, why in damaged[:20]:
        print(f"damaged: {Path(args.build) / rel}: {why}")
    if len(damaged) > 20:
        print(f"damaged: ... and {len(damaged) - 20} more")
    if not damaged:
        if not args.repair:        # make assets runs --repair each time: silent when nothing is wrong
            print(f"{Path(args.build) / 'manifest.json'}: every output matches")
        return 0
    if args.repair:
        steps = invalidate(args.build, damaged)
        print(f"{len(damaged)} damaged outputs removed; rebuilding with the steps writing {', '.join(steps)}")
        return 0
    return 1
