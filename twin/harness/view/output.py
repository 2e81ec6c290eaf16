"""A recording saved to an ``.rrd`` file (:func:`write_recording`, through a temporary file renamed
into place) or served over gRPC with a web viewer (:func:`serve_recording`).
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any
from urllib.parse import quote

from twin.harness.view.base import (
    APP_ID,
    ViewError,
    ViewSummary,
)
from twin.harness.view.recording import build


def _stream(directory: Path):
    import rerun as rr

    rec = rr.RecordingStream(APP_ID)
    rec.send_recording_name(f"twin view {directory.resolve().name}")
    return rec


def write_recording(directory: str | Path, out: str | Path | None = None, **options) -> ViewSummary:
    """Write the recording of ``directory`` to ``out`` (default ``directory/view.rrd``), through a
    temporary file renamed into place; options as :func:`build`. Returns the summary with
    ``path``, ``size_bytes`` and ``seconds`` (logging and writing)."""
    directory = Path(directory)
    out = Path(out) if out is not None else directory / "view.rrd"
    if not (directory / "measurements.h5").is_file():  # before creating anything
        raise FileNotFoundError(f"{directory / 'measurements.h5'}: no such file; expected the campaign's "
                                "measurements.h5 (`twin simulate SCENARIO -o DIR` writes one)")
    t0 = time.perf_counter()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".partial")
    rec = _stream(directory)
    rec.save(tmp)
    try:
        summary = build(rec, directory, **options)
        rec.flush()
    except BaseException:
        rec.disconnect()
        tmp.unlink(missing_ok=True)
        raise
    rec.disconnect()
    os.replace(tmp, out)
    summary.path, summary.size_bytes = out, out.stat().st_size
    summary.seconds = time.perf_counter() - t0
    return summary


def _check_port(port: int, option: str) -> None:
    """Raise :class:`ViewError` if TCP ``port`` cannot be bound (Rerun's gRPC server only logs it)."""
    import socket

    if not 0 < port < 65536:
        raise ViewError(f"{option} {port}: expected a TCP port 1-65535")
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("0.0.0.0", port))
        except OSError as exc:
            raise ViewError(f"{option} {port}: the port is not free ({exc.strerror}); choose another") from None


def serve_recording(directory: str | Path, *, web_port: int = 9090, grpc_port: int = 9876,
                    open_browser: bool = False, **options) -> tuple[ViewSummary, str, Any]:
    """Serve the recording of ``directory`` over gRPC with a web viewer on ``web_port``. Returns
    (summary, viewer URL, the recording stream); the servers live as long as the stream (the CLI
    keeps it until Ctrl-C)."""
    import rerun as rr

    directory = Path(directory)
    if not (directory / "measurements.h5").is_file():
        raise FileNotFoundError(f"{directory / 'measurements.h5'}: no such file; expected the campaign's "
                                "measurements.h5 (`twin simulate SCENARIO -o DIR` writes one)")
    for port, option in ((grpc_port, "--grpc-port"), (web_port, "--web-port")):
        _check_port(port, option)
    rec = _stream(directory)
    uri = rec.serve_grpc(grpc_port=grpc_port)
    summary = build(rec, directory, **options)
    rec.flush()
    try:
        rr.serve_web_viewer(web_port=web_port, open_browser=open_browser, connect_to=uri)
    except RuntimeError as exc:
        rec.disconnect()
        raise ViewError(f"--web-port {web_port}: the web viewer could not start ({exc})") from None
    return summary, f"http://localhost:{web_port}/?url={quote(uri, safe='')}", rec
