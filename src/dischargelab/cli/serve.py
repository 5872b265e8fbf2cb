"""``dischargelab serve``: the local web app (logbook pages and the live bench)."""

from __future__ import annotations

import click

from .common import CONTEXT, err, out


@click.command("serve", context_settings=CONTEXT)
@click.option("--db", metavar="URL",
              help="Logbook database: a SQLite file or a postgresql+psycopg:// URL (default: "
                   "$DISCHARGELAB_DB or logbook.sqlite in the user data folder).")
@click.option("--port", type=click.IntRange(0, 65535), default=8050, show_default=True,
              help="TCP port (0 picks a free one).")
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Address to listen on. Anything but loopback lets other machines in and "
                   "needs --token.")
@click.option("--token", is_flag=False, flag_value="auto", default=None, metavar="[TOKEN]",
              help="Require this token on every request; --token alone makes a random one "
                   "(printed in the address).")
@click.option("--demo", is_flag=True,
              help="The live page's Start runs a virtual logger (a simulated pack on a "
                   "pseudo-terminal) through the real acquisition: try it without hardware.")
@click.option("--runs", "runs_dir", type=click.Path(file_okay=False), metavar="DIR",
              help="Folder of the demo runs' log files (default: a new temporary folder).")
@click.option("--max-upload", "max_upload_MB", type=click.FloatRange(min=0.001), default=64.0,
              show_default=True, metavar="MB", help="Largest log file accepted by the upload.")
@click.option("--header-timeout", "header_timeout_s", type=click.FloatRange(min=0.1),
              default=10.0, show_default=True, metavar="S",
              help="Time a connection gets to send a whole request head; idle and half-sent "
                   "connections are closed after it.")
@click.option("--body-timeout", "body_timeout_s", type=click.FloatRange(min=0.1), default=20.0,
              show_default=True, metavar="S",
              help="Time a request body may take, plus 1 s per 500 bytes received; slower "
                   "bodies are cut off (408).")
@click.option("--public-host", "public_hosts", multiple=True, metavar="NAME",
              help="Host name the server also answers to, as a reverse proxy in front passes "
                   "it on (e.g. dl.example.org); repeat for more.")
@click.option("--max-connections", type=click.IntRange(1), default=1000, show_default=True,
              metavar="N", help="Open connections at most; more are answered 503.")
@click.option("--max-per-client", type=click.IntRange(0), default=0, show_default=True,
              metavar="N", help="Open connections from one address at most (429 beyond); 0 "
                                "= no cap. Keep 0 behind a reverse proxy.")
def serve_cmd(db, port, host, token, demo, runs_dir, max_upload_MB, header_timeout_s,
              body_timeout_s, public_hosts, max_connections, max_per_client):
    """Serve the logbook's pages and the live test bench in a browser.

    Pages: / (packs: health, EFC, forecast end of life), /packs/NAME (capacity
    and resistance against EFC, events, model curves, fit and endurance), /live
    (the live bench). Everything ships with dischargelab and works offline.
    Listens on 127.0.0.1 only unless --host says otherwise, which needs --token.
    Slow and idle connections are closed (--header-timeout, --body-timeout);
    for a team, run it behind a reverse proxy (docs/web.md). Ctrl-C stops.

    \b
    Examples:
      dischargelab serve
      dischargelab serve --demo                      # live page with a virtual logger
      dischargelab serve --db runs.sqlite --port 8080
      dischargelab serve --host 0.0.0.0 --token      # reachable on the network, token required
      dischargelab serve --token --public-host dl.example.org   # behind nginx or Caddy
      dischargelab serve --host 0.0.0.0 --token --max-per-client 32   # no proxy
      dischargelab acquire --port /dev/ttyACM0 --out run.csv --ke 4.38 --serve
    """
    from ..errors import DischargelabError
    from ..web.limits import Limits
    from ..web.server import build_server, is_loopback

    if not is_loopback(host) and not token:
        raise DischargelabError(f"--host {host} lets other machines reach the server: add "
                                "--token (or keep the default --host 127.0.0.1)")
    limits = Limits(max_upload_bytes=int(max_upload_MB * 1024 * 1024),
                    header_timeout_s=header_timeout_s, body_timeout_s=body_timeout_s,
                    max_connections=max_connections,
                    max_connections_per_client=max_per_client)
    server = build_server(db=db, host=host, port=port, token=token, demo=demo, runs=runs_dir,
                          limits=limits, public_hosts=public_hosts)
    listening = server.listening
    out.print(f"dischargelab serve: listening on {listening.url}", markup=False)
    if demo:
        runs = server.app_state("bench").run_dir
        out.print(f"live bench (demo): {listening.page('live')}; run logs go to {runs}",
                  markup=False)
    if not is_loopback(host):
        err.print(f"note: listening on {host}: other machines can reach this server; every "
                  "request needs the token (the address above carries it)", markup=False)
    out.print("Ctrl-C stops.", markup=False)
    server.run()


COMMANDS = [serve_cmd]
