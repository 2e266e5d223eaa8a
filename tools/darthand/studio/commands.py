"""The `darthand studio` command: open a build, serve the page until Ctrl-C. Its options are defined in cli.py. The
handler imports the studio lazily, when it runs, so `darthand --help` does not load the renderer."""

from __future__ import annotations

import signal
import sys

from darthand.errors import InputError


def studio(args) -> int:
    """Serve the studio page over BUILD on --host:--port; print the address; stop cleanly on Ctrl-C or SIGTERM."""
    from darthand.studio.build import StudioBuild
    from darthand.studio.server import Studio, make_server

    if args.port is not None and not 0 <= args.port <= 65535:
        raise InputError(f"--port: {args.port} is outside 0..65535")
    if args.host not in ("127.0.0.1", "localhost", "::1") and not args.allow_remote:
        raise InputError(f"--host {args.host}: the studio listens on this machine only unless --allow-remote is "
                         "given (it serves the build folder to anyone who can reach the address)")
    build = StudioBuild(args.build, backgrounds=args.backgrounds, environments=args.environments,
                        objects=args.objects_catalog, grasps=args.grasps_catalog)
    server = make_server(Studio(build), args.host, args.port or 0)
    server.RequestHandlerClass.quiet = not args.verbose  # type: ignore[attr-defined]  # StudioHandler.quiet
    host, port = server.server_address[:2]
    assert isinstance(host, str), "an IP server's host is a string"
    print(f"[studio] {build.root}: sides {', '.join(build.sides)}; open http://{host}:{port}/ (Ctrl-C stops)",
          flush=True)
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        server.serve_forever(poll_interval=0.2)
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        server.server_close()
    print("[studio] stopped", file=sys.stderr, flush=True)
    return 0


def _interrupt(signum, frame):
    raise KeyboardInterrupt
