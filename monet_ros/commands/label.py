"""`monet label REC --labels labels.csv`: label keypoints in a browser, with geometry assist.

    monet label REC --labels labels.csv [--rig RIG] [--skeleton human14] [--model CKPT]
        [--import FORMAT=PATH] [--port 8080] [--host 127.0.0.1] [--allow-host NAME]

Serves a local web page (monet_ros.label_app; every asset ships in the package, no CDN)
showing every camera of one instant side by side. Click a keypoint in two views: it is
triangulated (the project's robust triangulation) and its projection appears as a ghost in
every other view ('a' accepts them); each view shows its reprojection error and views that
disagree beyond --flag-px are flagged; epipolar curves of the selected keypoint guide the
click. Every change is saved at once (atomically) to the --labels table (the canonical
stamp_ns,camera,keypoint,u,v CSV of monet_ros.labels); existing labels there, or in
another tool's format (--import), are loaded through the one label validator.
Suggested instants are spread over time and pose: k-means on the detector's 3D output with
--model (which also pre-fills unlabelled instants from the detector's peaks and shows each
instant's disagreement), else on image thumbnails.

Binds 127.0.0.1 by default: on a remote machine, forward the port over SSH
(ssh -L 8080:localhost:8080 host) and open http://localhost:8080. Only the names
localhost, 127.0.0.1, [::1], the --host address and --allow-host names are served (other
Host headers get 421: DNS rebinding); changes need the page's per-run token
(monet_ros.label_app.guard).
"""
import os
import re
import sys

HELP = 'label keypoints in a browser: click two views, the others are filled in by geometry'


def add_arguments(parser):
    from monet_ros.commands.labels import add_label_arguments
    from monet_ros.label_app.session import LabelConfig
    from monet_ros.labels_import import FORMATS

    d = LabelConfig.__dataclass_fields__
    parser.add_argument('rec', help='recording: rosbag2 folder, .mcap or `monet synth` folder')
    parser.add_argument('--labels', required=True, help='labels CSV to edit and autosave '
                        '(stamp_ns,camera,keypoint,u,v; read first when it exists)')
    parser.add_argument('--import', dest='imports', action='append', default=[],
                        metavar='FORMAT=PATH', help='existing labels in another format to '
                        f'load ({", ".join(sorted(FORMATS))}; repeatable)')
    parser.add_argument('--rig', help="rig file (default: the recording's)")
    from monet_ros.commands.common import add_rig_units_argument
    add_rig_units_argument(parser)
    parser.add_argument('--skeleton', default='human14', help='skeleton preset or YAML')
    parser.add_argument('--model', help='detector checkpoint: suggestions from its 3D output, '
                        'pre-filled peaks and per-instant disagreement')
    parser.add_argument('--device', default=None, help='torch device of --model (auto, cpu, '
                        'cuda:N)')
    parser.add_argument('--port', type=int, default=8080, help='TCP port (default 8080)')
    parser.add_argument('--host', default='127.0.0.1', help='address to bind (default '
                        '127.0.0.1: this machine only; use SSH port forwarding)')
    parser.add_argument('--allow-host', action='append', default=[], metavar='NAME',
                        help='another host name the page may be opened by (e.g. this '
                        "machine's name with --host 0.0.0.0; repeatable). Besides it only "
                        'localhost, 127.0.0.1, [::1] and --host are served')
    parser.add_argument('--flag-px', type=float, default=d['flag_px'].default,
                        help=d['flag_px'].metadata['description'])
    parser.add_argument('--threshold-px', type=float, default=d['threshold_px'].default,
                        help=d['threshold_px'].metadata['description'])
    parser.add_argument('--suggestions', type=int, default=d['suggestions'].default,
                        help=d['suggestions'].metadata['description'])
    add_label_arguments(parser)


def _imports(items):
    from monet_ros.config import ConfigError
    from monet_ros.labels_import import FORMATS

    out = []
    for item in items:
        fmt, sep, path = str(item).partition('=')
        if not sep or fmt not in FORMATS or not path:
            raise ConfigError('monet label', 'import', f'{item!r}: expected FORMAT=PATH with '
                              f'FORMAT one of {", ".join(sorted(FORMATS))}')
        out.append((fmt, path))
    return out


def _bind_blame(error):
    """The option a failed bind is the fault of: 'host' when the address is not one of this
    machine or not a name that resolves (EADDRNOTAVAIL, a resolver error), else 'port' (in
    use, privileged)."""
    import errno
    import socket
    # socket.create_server re-raises getaddrinfo's errors as OSError with their (negative)
    # EAI_* code
    resolver = isinstance(error, socket.gaierror) or (isinstance(error.errno, int)
                                                      and error.errno < 0)
    if resolver or error.errno in (errno.EADDRNOTAVAIL, errno.EAFNOSUPPORT):
        return 'host'
    return 'port'


def run(args):
    from monet_ros.commands.labels import label_options_from_args
    from monet_ros.config import ConfigError
    from monet_ros.label_app.guard import WILDCARD, allowed_hosts
    from monet_ros.label_app.server import create_app
    from monet_ros.label_app.session import LabelConfig, LabelSession
    from monet_ros.models.device import check_device

    if not 0 <= args.port <= 65535:
        raise ConfigError('monet label', 'port', f'must be in 0..65535, got {args.port}')
    for name in args.allow_host:
        # a DNS name or IPv4 address, or an IPv6 address (bare or in brackets)
        if not re.fullmatch(r'[A-Za-z0-9_.-]+|\[?[0-9A-Fa-f:.]*:[0-9A-Fa-f:.]*\]?', name):
            raise ConfigError('monet label', 'allow_host', f'{name!r}: expected a host name '
                              'or address (no scheme, port or path; IPv6 in [ ])')
    config = LabelConfig(flag_px=args.flag_px, threshold_px=args.threshold_px,
                         suggestions=args.suggestions)
    device = check_device('monet label', args.device) if args.model else None
    if args.model:
        from monet_ros.models.checkpoint import read_checkpoint
        read_checkpoint(args.model)        # a bad file is named before the recording loads
    session = LabelSession(args.rec, args.labels, rig=args.rig, rig_units=args.rig_units,
                           skeleton=args.skeleton,
                           imports=_imports(args.imports),
                           options=label_options_from_args(args), config=config)
    predictor = None
    if args.model:
        from monet_ros.label_app.suggest import Predictor
        predictor = Predictor(session, args.model, device=device)
    import logging
    import socket

    from werkzeug.serving import make_server
    logging.getLogger('werkzeug').setLevel(logging.WARNING)    # no line per request
    try:     # our own socket: its error names the address (werkzeug's would exit 1)
        listener = socket.create_server((args.host, args.port))
    except OSError as error:
        raise ConfigError('monet label', _bind_blame(error),
                          f'cannot listen on {args.host}:{args.port} '
                          f'({error.strerror or error})') from None
    port = listener.getsockname()[1]                   # --port 0: the one given
    app = create_app(session, allowed_hosts(args.host, port, args.allow_host), predictor)
    server = make_server(args.host, args.port, app, threaded=True, fd=listener.fileno())
    host, port = server.server_address[:2]
    print(f'monet label: {len(session.stamps)} instants x {len(session.cameras)} cameras, '
          f'{len(session.labelled_instants())} labelled ({session.report}); '
          f'labels -> {session.labels_path}', flush=True)
    for note in session.notes:
        print(f'monet label: note: {note}', flush=True)
    if args.host not in ('127.0.0.1', 'localhost', '::1'):
        print(f'monet label: note: bound to {args.host}: anyone who reaches this port can '
              'read the images and change the labels (no authentication); host names '
              f'served: {", ".join(sorted(app.config["MONET_HOSTS"]))}', flush=True)
    if host in WILDCARD:                   # every interface: open it by a served name
        host = 'localhost'
    elif ':' in host:
        host = f'[{host}]'
    print(f'monet label: serving http://{host}:{port}/ (Ctrl-C to stop)', flush=True)
    try:
        server.serve_forever()
    finally:
        session.stopping.set()          # long jobs end at their next instant ...
        server.server_close()
        if session.work.acquire(timeout=30):   # ... never cut inside a native library
            session.work.release()
    # werkzeug's serve_forever returns on Ctrl-C / SIGTERM (it catches KeyboardInterrupt)
    print('monet label: stopped', file=sys.stderr, flush=True)
    if 'torch' in sys.modules:
        # with a model loaded, a native thread pool destroyed at interpreter exit aborted
        # now and then ("terminate called without an active exception", exit -6); every
        # label is saved and the streams are flushed, so leave without the C++ teardown
        sys.stdout.flush()
        os._exit(0)
    return 0
