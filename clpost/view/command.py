"""``clpost view [INPUT] [--port N] [--no-browser]``: the camera, live, in a browser."""
from __future__ import annotations

import socket
import sys

from ..errors import InputError

HOST = "127.0.0.1"
"""Loopback only: the viewer reads and writes files as the user; nothing else may reach it."""

DEFAULT_PORT = 8765

VIEW_CAMERA_DEFAULTS = dict(lens="thin:50", depth_of_field=True, vignetting="natural", f_number=2.0,
                            shutter_s=None, focus_distance_m=3.0, luminance_scale=1000.0,
                            exposure_compensation_ev=1.0, blades=6)
"""The demo's camera (:data:`clpost.demo.DEMO_CAMERA_DEFAULTS`) with a thin 50 mm lens: every
control then moves the image within the draft budget (a traced lens re-traces its field
aberrations per focus and f-number, ~1 s; choose one with --lens or the lens control)."""


def add_parser(sub, size, options) -> None:
    """Register ``clpost view`` (``size`` parses WxH; ``options`` are the CLI's generated camera
    options, :func:`clpost.cli.camera_options`, handed in so this module does not import the CLI)."""
    p = sub.add_parser(
        "view", help="the camera live in a browser: drag every parameter, tap to focus (local web app)",
        description="Starts a local web app on 127.0.0.1 showing the processed frame while you drag the "
                    "camera's controls (docs/view.md). Without INPUT: the built-in demo scene.")
    p.add_argument("input", nargs="?", default=None,
                   help="input EXR or pattern (in.####.exr) as for clpost process (default: the demo scene)")
    p.add_argument("--port", type=_port, default=DEFAULT_PORT, help=f"port on 127.0.0.1 (default {DEFAULT_PORT}; 0: any free port)")
    p.add_argument("--no-browser", action="store_true", help="print the URL only; do not open a browser")
    p.add_argument("--size", type=size, default=None,
                   help="WIDTHxHEIGHT of the demo scene (default 960x540; an INPUT keeps its own)")
    p.add_argument("--frames", type=int, default=None, metavar="N", help="demo scene frames to scrub (default 5)")
    p.add_argument("--channels", default=None, help="input channel layout: clpost, blender, nuke, arnold (default: detect)")
    p.add_argument("--quality", choices=("draft", "preview", "final"), default="final",
                   help="quality rendered when the controls are idle (dragging always renders draft)")
    import argparse

    g = p.add_argument_group("camera (the starting values, the page changes them; defaults without INPUT: "
                             "the demo camera with a thin 50 mm lens)")
    for flag, dest, typ, help_ in options:
        g.add_argument(flag, dest=f"cam_{dest}", type=typ, default=argparse.SUPPRESS, help=help_)
    p.set_defaults(func=cmd_view)


def _port(text: str) -> int:
    import argparse

    try:
        n = int(text)
    except ValueError:
        n = -1
    if not 0 <= n <= 65535:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port number (0-65535; 0: any free port)")
    return n


def _check_port(port: int) -> int:
    """The port to listen on (a free one for 0); InputError naming it when it is taken."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind((HOST, port))
        except OSError:
            raise InputError(f"--port {port}: {HOST}:{port} is in use; choose another port "
                             "(or --port 0 for any free one)") from None
        return s.getsockname()[1]


def cmd_view(args) -> int:
    from ..camera import Camera

    try:
        import trame  # noqa: F401
        import trame_vuetify  # noqa: F401
    except ImportError:
        raise InputError("clpost view needs trame: pip install 'clpost[view]'") from None
    from .session import DEMO_FRAMES, DEMO_SIZE, ViewSession, open_input

    given = {k[4:]: v for k, v in vars(args).items() if k.startswith("cam_")}  # as clpost.cli.camera_from_args
    camera = Camera.from_options(given, None if args.input else VIEW_CAMERA_DEFAULTS)
    if args.input is not None and (args.size or args.frames):
        raise InputError("--size and --frames shape the demo scene; an INPUT is shown at its own size, all frames")
    port = _check_port(args.port)
    numbers, load, label = open_input(args.input, camera, size=args.size or DEMO_SIZE,
                                      n_frames=args.frames or DEMO_FRAMES, channels=args.channels)
    session = ViewSession(numbers, load, camera, label, final_quality=args.quality, device=args.device)
    return serve(session, port, open_browser=not args.no_browser)


def serve(session, port: int, open_browser: bool = True) -> int:
    """Run the page until SIGINT (Ctrl-C) or SIGTERM; prints the URL first."""
    from .app import ViewApp

    app = ViewApp(session)
    server = app.server

    def ready(**_):
        url = f"http://{HOST}:{server.port}/"
        print(f"clpost view: {url} (Ctrl-C stops)", flush=True)
        if open_browser:
            import webbrowser

            webbrowser.open(url)

    server.controller.on_server_ready.add(ready)
    argv = sys.argv
    sys.argv = argv[:1]  # trame reads its own options from sys.argv: give it none of clpost's
    try:
        server.start(port=port, host=HOST, open_browser=False, show_connection_info=False, timeout=0,
                     disable_logging=True)
    finally:
        sys.argv = argv
        app.close()
    print("clpost view: stopped", flush=True)
    return 0
