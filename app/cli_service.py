"""`squashcal run | serve | worker | migrate | keys`: the service's commands.

Top-level imports stay light (argparse only); each command imports what it needs when it runs.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from app.settings import Settings


def add_arguments(command: str, parser: argparse.ArgumentParser) -> None:
    if command in ("run", "serve"):
        parser.add_argument("--host", default=None, help="bind address (default SQUASHCAL_HOST)")
        parser.add_argument("--port", type=int, default=None, help="port (default SQUASHCAL_PORT)")
    if command == "run":
        parser.add_argument(
            "--workers", type=int, default=1, help="worker processes to start (default 1)"
        )
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
        return _serve(settings, args.host, args.port)
    if command == "worker":
        from worker.main import run_worker

        return run_worker(settings, once=args.once, worker_id=args.worker_id)
    if command == "keys":
        return _keys(settings, args)
    if command == "run":
        return _run_all(settings, args.host, args.port, args.workers)
    raise ValueError(f"unknown command {command!r}")


def _migrate(settings: Settings) -> int:
    from app.db.migrate import upgrade_head

    revision = upgrade_head(settings)
    print(f"database at revision {revision} ({_safe_url(settings.sqlalchemy_url)})")
    return 0


def _serve(settings: Settings, host: str | None, port: int | None) -> int:
    import uvicorn

    from app.main import create_app

    uvicorn.run(
        create_app(settings, warm_up=settings.warm_up),
        host=host or settings.host,
        port=port or settings.port,
        log_level="info",
        # SIGTERM: stop accepting, finish in-flight requests (uploads) for up to this long
        timeout_graceful_shutdown=30,
    )
    return 0


def _keys(settings: Settings, args: argparse.Namespace) -> int:
    from app.db import repo
    from app.db.session import make_engine, make_sessionmaker

    engine = make_engine(settings)
    sessions = make_sessionmaker(engine)
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


def _run_all(settings: Settings, host: str | None, port: int | None, n_workers: int) -> int:
    """Migrate, start `n_workers` worker processes and the API, restart any that exits (with
    backoff); stop them all on Ctrl-C/SIGTERM."""
    from app.supervisor import Supervisor

    _migrate(settings)
    host = host or settings.host
    port = port or settings.port
    children = {
        "api": [sys.executable, "-m", "app.cli", "serve", "--host", host, "--port", str(port)]
    }
    for i in range(max(0, n_workers)):
        children[f"worker-{i + 1}"] = [sys.executable, "-m", "worker"]
    supervisor = Supervisor(
        children,
        env=os.environ.copy(),
        say=lambda message: print(f"squashcal run: {message}", flush=True),
    )

    def _stop(signum: int, frame: object) -> None:
        supervisor.stop()

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    supervisor.start()
    shown_host = "127.0.0.1" if host in ("0.0.0.0", "::") else host
    print(
        f"\nsquashcal API on http://{shown_host}:{port}  (OpenAPI: /docs, upload page: /)\n"
        f"{n_workers} worker process(es) running; data in {settings.data_dir.resolve()}\n"
        "authenticate with an API key:  .venv/bin/squashcal keys create --name me\n"
        "  then send 'Authorization: Bearer <key>' (the last line that command prints)\n",
        flush=True,
    )
    try:
        supervisor.run()
    finally:
        # workers get their grace period to finish or give back their jobs
        supervisor.terminate_all(timeout_s=settings.shutdown_grace_s + 10)
    return 0


def _safe_url(url: str) -> str:
    from sqlalchemy.engine import make_url

    return make_url(url).render_as_string(hide_password=True)
