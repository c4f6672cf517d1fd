"""`squashcal run | serve | worker | migrate | keys`: the service's commands.

Top-level imports stay light (argparse only); each command imports what it needs when it runs.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import socket

    from app.settings import Settings
    from app.supervisor import Supervisor

DEFAULT_APP_FACTORY = "app.main:served_app"


def add_arguments(command: str, parser: argparse.ArgumentParser) -> None:
    if command in ("run", "serve"):
        parser.add_argument("--host", default=None, help="bind address (default SQUASHCAL_HOST)")
        parser.add_argument("--port", type=int, default=None, help="port (default SQUASHCAL_PORT)")
    if command == "run":
        parser.add_argument(
            "--workers", type=int, default=1, help="worker processes to start (default 1)"
        )
        parser.add_argument(
            "--api-workers",
            type=_positive,
            default=1,
            help="API processes sharing the port (SO_REUSEPORT; default 1)",
        )
    if command == "serve":
        parser.add_argument(
            "--workers",
            type=_positive,
            default=1,
            help="API processes sharing the port, each supervised (SO_REUSEPORT; default 1)",
        )
        parser.add_argument("--log-level", default="info", help="uvicorn log level")
        parser.add_argument("--no-access-log", action="store_true", help="no line per request")
        # internal: one of several API processes on one port (what --workers starts)
        parser.add_argument("--reuse-port", action="store_true", help=argparse.SUPPRESS)
        # benchmarks: serve another app factory (module:function) the same way
        parser.add_argument("--app-factory", default=DEFAULT_APP_FACTORY, help=argparse.SUPPRESS)
    if command == "worker":
        parser.add_argument(
            "--once", action="store_true", help="process at most one job, then exit"
        )
        parser.add_argument("--worker-id", default=None, help="name shown in jobs.worker_id")
    if command == "keys":
        sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
        create = sub.add_parser("create", help="create an API key; prints it as the last line")
        create.add_argument("--name", required=True, help="a label for the key")
        create.add_argument(
            "--tenant",
            default=None,
            help="add the key to this existing tenant id (default: a new tenant named NAME)",
        )
        sub.add_parser("list", help="list API keys (never the keys themselves)")
        revoke = sub.add_parser("revoke", help="revoke an API key by its id")
        revoke.add_argument("key_id")


def run(command: str, args: argparse.Namespace) -> int:
    from app.settings import get_settings

    settings = get_settings()
    if command == "migrate":
        return _migrate(settings)
    if command == "serve":
        if args.workers > 1:
            return _serve_many(settings, args)
        return _serve(settings, args)
    if command == "worker":
        from worker.main import run_worker

        return run_worker(settings, once=args.once, worker_id=args.worker_id)
    if command == "keys":
        return _keys(settings, args)
    if command == "run":
        return _run_all(settings, args.host, args.port, args.workers, args.api_workers)
    raise ValueError(f"unknown command {command!r}")


def _migrate(settings: Settings) -> int:
    from app.db.migrate import upgrade_head

    revision = upgrade_head(settings)
    print(f"database at revision {revision} ({_safe_url(settings.sqlalchemy_url)})")
    return 0


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError("must be at least 1")
    return value


def _serve(settings: Settings, args: argparse.Namespace) -> int:
    """One API process (the app from `--app-factory`); with `--reuse-port` it shares the port
    with the other API processes of `serve --workers N`."""
    import uvicorn

    host = args.host or settings.host
    port = args.port or settings.port
    config = uvicorn.Config(
        args.app_factory,
        factory=True,
        host=host,
        port=port,
        log_level=args.log_level,
        access_log=not args.no_access_log,
        # SIGTERM: stop accepting, finish in-flight requests (uploads) for up to this long
        timeout_graceful_shutdown=30,
    )
    server = uvicorn.Server(config)
    sockets = [reuse_port_socket(host, port)] if args.reuse_port else None
    server.run(sockets=sockets)
    return 0


def reuse_port_socket(host: str, port: int) -> socket.socket:
    """A listening TCP socket with SO_REUSEPORT: each API process binds its own on one port and
    the kernel spreads new connections over them (by a hash of the client's address and port).
    Only processes of the same user can join the port."""
    import socket

    family, kind, proto, _, address = socket.getaddrinfo(
        host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
    )[0]
    sock = socket.socket(family, kind, proto)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
    if family == socket.AF_INET6:
        sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 0)
    sock.bind(address)
    sock.listen(2048)
    sock.set_inheritable(True)
    return sock


def api_process_argv(
    host: str, port: int, extra: Sequence[str] = (), reuse_port: bool = False
) -> list[str]:
    argv = [sys.executable, "-m", "app.cli", "serve", "--host", host, "--port", str(port)]
    return argv + (["--reuse-port"] if reuse_port else []) + list(extra)


def _serve_many(settings: Settings, args: argparse.Namespace) -> int:
    """`serve --workers N`: N API processes on one port (SO_REUSEPORT), each restarted with
    backoff if it exits, all stopped on SIGTERM/SIGINT."""
    from app.supervisor import Supervisor

    host = args.host or settings.host
    port = args.port or settings.port
    extra = ["--log-level", args.log_level, "--app-factory", args.app_factory]
    if args.no_access_log:
        extra.append("--no-access-log")
    children = {
        f"api-{i + 1}": api_process_argv(host, port, extra, reuse_port=True)
        for i in range(args.workers)
    }
    supervisor = Supervisor(
        children,
        env=os.environ.copy(),
        say=lambda message: print(f"squashcal serve: {message}", flush=True),
    )
    return _supervise(supervisor, settings, banner=None)


def _supervise(supervisor: Supervisor, settings: Settings, banner: str | None) -> int:
    def _stop(signum: int, frame: object) -> None:
        supervisor.stop()

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    supervisor.start()
    if banner:
        print(banner, flush=True)
    try:
        supervisor.run()
    finally:
        # workers get their grace period to finish or give back their jobs; API processes
        # theirs to finish requests in flight
        supervisor.terminate_all(timeout_s=max(settings.shutdown_grace_s, 30) + 10)
    return 0


def _keys(settings: Settings, args: argparse.Namespace) -> int:
    from app.db import repo
    from app.db.session import make_engine, make_sessionmaker, write_engine

    engine = make_engine(settings)
    # creating or revoking a key reads (the tenant, the key) and then writes: like the API's
    # such transactions, it takes SQLite's write lock at BEGIN (see AppState.write_sessions)
    sessions = make_sessionmaker(write_engine(engine))
    try:
        with sessions.begin() as session:
            if args.action == "create":
                key_row, key = repo.create_api_key(session, name=args.name, tenant_id=args.tenant)
                print(f"created API key {key_row.id} for tenant {key_row.tenant_id}")
                print("use it as: Authorization: Bearer <key>   (shown only once)")
                print(key)
            elif args.action == "list":
                for row in repo.list_api_keys(session):
                    state = "revoked" if row.revoked_at else "active"
                    print(f"{row.id}  tenant={row.tenant_id}  name={row.name!r}  {state}")
            elif args.action == "revoke":
                if not repo.revoke_api_key(session, args.key_id):
                    print(f"no active key with id {args.key_id}", file=sys.stderr)
                    return 1
                print(f"revoked {args.key_id}")
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    finally:
        engine.dispose()
    return 0


def _run_all(
    settings: Settings, host: str | None, port: int | None, n_workers: int, n_api: int = 1
) -> int:
    """Migrate, start `n_workers` worker processes and `n_api` API processes (sharing the port),
    restart any that exits (with backoff); stop them all on Ctrl-C/SIGTERM."""
    from app.supervisor import Supervisor

    _migrate(settings)
    host = host or settings.host
    port = port or settings.port
    if n_api == 1:
        children = {"api": api_process_argv(host, port)}
    else:
        children = {
            f"api-{i + 1}": api_process_argv(host, port, reuse_port=True) for i in range(n_api)
        }
    for i in range(max(0, n_workers)):
        children[f"worker-{i + 1}"] = [sys.executable, "-m", "worker"]
    supervisor = Supervisor(
        children,
        env=os.environ.copy(),
        say=lambda message: print(f"squashcal run: {message}", flush=True),
    )
    shown_host = "127.0.0.1" if host in ("0.0.0.0", "::") else host
    banner = (
        f"\nsquashcal API on http://{shown_host}:{port}  (OpenAPI: /docs, upload page: /)\n"
        f"{n_api} API process(es), {n_workers} worker process(es) running; "
        f"data in {settings.data_dir.resolve()}\n"
        "authenticate with an API key:  .venv/bin/squashcal keys create --name me\n"
        "  then send 'Authorization: Bearer <key>' (the last line that command prints)\n"
    )
    return _supervise(supervisor, settings, banner)


def _safe_url(url: str) -> str:
    from sqlalchemy.engine import make_url

    return make_url(url).render_as_string(hide_password=True)
