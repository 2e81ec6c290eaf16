"""A warm ``python -m twin.cli`` for the suite: each call runs in a process forked from a server
that has imported the heavy libraries once, instead of a new interpreter importing them again.

The suite calls the command line a few hundred times, and a verb's imports (NumPy, SciPy,
scikit-learn, h5py, MuJoCo, Matplotlib) cost about 2 to 3.5 s of CPU each time, a large share of
`make test`. The call is still a process of its own, as `python -m twin.cli` would be: forked
from the server (a single-threaded process that has imported only third-party libraries, none of
``twin`` or ``analysis``), it takes the caller's environment, working directory and arguments,
writes its standard output and error to files of its own, runs ``twin.cli`` as ``__main__``
(:func:`runpy.run_module`, as ``-m`` does) and exits with its code. The call's import path is
a new interpreter's (its working directory, its PYTHONPATH, the standard library and
site-packages); a test that needs a new interpreter (one that hides optional modules) runs
:func:`subprocess.run` itself.

One server per test process, started on the first call and stopped when the test process ends
(the server leaves when its standard input closes). Each request is handled by a child of the
server (the "manager"), which forks the call's process, tells the caller its pid, waits for it
and sends its exit code; so calls from several threads of a test run side by side.
"""

from __future__ import annotations

import atexit
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: What the server imports before it forks: the third-party libraries the verbs import.
PRELOAD = ("numpy", "scipy.signal", "scipy.stats", "scipy.optimize", "scipy.interpolate", "scipy.special",
           "scipy.linalg", "scipy.ndimage", "sklearn.base", "sklearn.decomposition", "sklearn.mixture",
           "sklearn.svm", "sklearn.neural_network", "sklearn.preprocessing", "sklearn.utils.validation",
           "h5py", "mujoco", "matplotlib", "matplotlib.pyplot", "pydantic", "typer", "rich.console",
           "threadpoolctl", "tomllib")


#: The server's import path without its working directory and PYTHONPATH (set by :func:`serve`).
_BASE_PATH: list[str] = []


def _recv_line(conn: socket.socket, buf: bytearray) -> bytes:
    while b"\n" not in buf:
        chunk = conn.recv(65536)
        if not chunk:
            raise ConnectionError("the twin call server closed the connection")
        buf += chunk
    line, _, rest = bytes(buf).partition(b"\n")
    buf[:] = rest
    return line


def _run_call(req: dict) -> None:
    """In the call's process: become ``python -m twin.cli ARGS`` and exit with its code."""
    import runpy
    import signal
    import traceback

    os.setsid()  # its own process group: a timeout kills the call and the workers it started
    for fd, path, flags in ((0, os.devnull, os.O_RDONLY), (1, req["out"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC),
                            (2, req["err"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC)):
        new = os.open(path, flags, 0o600)
        os.dup2(new, fd)
        os.close(new)
    os.chdir(req["cwd"])
    os.environ.clear()
    os.environ.update(req["env"])
    signal.signal(signal.SIGINT, signal.default_int_handler)
    for sig in (signal.SIGCHLD, signal.SIGTERM, signal.SIGPIPE):
        signal.signal(sig, signal.SIG_DFL)
    # as a new interpreter's: `python -m` puts the working directory first, then PYTHONPATH's
    sys.path[:] = [req["cwd"], *(p for p in req["env"].get("PYTHONPATH", "").split(os.pathsep) if p), *_BASE_PATH]
    sys.argv = ["twin", *req["args"]]
    code = 0
    try:
        runpy.run_module("twin.cli", run_name="__main__", alter_sys=True)
    except SystemExit as exc:
        if exc.code is None:
            code = 0
        elif isinstance(exc.code, int):
            code = exc.code
        else:
            print(exc.code, file=sys.stderr)
            code = 1
    except BaseException:  # noqa: BLE001 - as the interpreter does for an uncaught exception
        traceback.print_exc()
        code = 1
    try:
        atexit._run_exitfuncs()
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:  # noqa: BLE001
                pass
        os._exit(code)


def _manage(conn: socket.socket) -> None:
    """In the request's manager: fork the call, send its pid, wait for it, send its exit code."""
    buf = bytearray()
    req = json.loads(_recv_line(conn, buf))
    pid = os.fork()
    if pid == 0:
        conn.close()
        _run_call(req)
    conn.sendall(json.dumps({"pid": pid}).encode() + b"\n")
    _, status = os.waitpid(pid, 0)
    conn.sendall(json.dumps({"returncode": os.waitstatus_to_exitcode(status)}).encode() + b"\n")


def serve(path: str) -> None:
    """The server: import :data:`PRELOAD`, then fork a manager per connection until standard
    input closes (the test process has ended)."""
    import importlib
    import select

    global _BASE_PATH
    own = {"", os.getcwd(), str(Path(__file__).parent), *os.environ.get("PYTHONPATH", "").split(os.pathsep)}
    _BASE_PATH = [p for p in sys.path if p not in own]  # the standard library and site-packages
    for name in PRELOAD:
        importlib.import_module(name)
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.bind(path + ".tmp")
    os.rename(path + ".tmp", path)  # the caller waits for the path: it appears when listening
    sock.listen(64)
    while True:
        ready, _, _ = select.select([sock, sys.stdin], [], [], 1.0)
        if sys.stdin in ready and not os.read(sys.stdin.fileno(), 1):
            return
        if sock in ready:
            conn, _ = sock.accept()
            if os.fork() == 0:
                sock.close()
                try:
                    _manage(conn)
                finally:
                    os._exit(0)
            conn.close()
        try:
            while os.waitpid(-1, os.WNOHANG)[0]:
                pass
        except ChildProcessError:
            pass


class CallServer:
    """The test process's handle on its server (:func:`call` starts it on first use)."""

    def __init__(self, cwd: Path, env: dict[str, str]):
        self.last_pid: int | None = None  # the last call's process
        self.dir = tempfile.mkdtemp(prefix="twin-calls-")
        self.path = os.path.join(self.dir, "socket")
        boot = f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import cli_server; " \
               f"cli_server.serve({self.path!r})"
        # one BLAS thread where the libraries are loaded: the forked calls set their own limits
        # (twin.cli.main) and start their workers with the caller's environment
        self.proc = subprocess.Popen([sys.executable, "-c", boot], stdin=subprocess.PIPE, cwd=cwd,
                                     env={**env, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})
        t0 = time.monotonic()
        while not os.path.exists(self.path):
            if self.proc.poll() is not None or time.monotonic() - t0 > 120:
                raise RuntimeError(f"the twin call server did not start (exit {self.proc.poll()})")
            time.sleep(0.05)

    def run(self, args: list[str], env: dict[str, str], cwd: Path,
            timeout: float | None = None) -> subprocess.CompletedProcess:
        out = tempfile.NamedTemporaryFile(dir=self.dir, delete=False)
        err = tempfile.NamedTemporaryFile(dir=self.dir, delete=False)
        out.close()
        err.close()
        try:
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as conn:
                conn.connect(self.path)
                conn.sendall(json.dumps({"args": args, "env": env, "cwd": str(cwd), "out": out.name,
                                         "err": err.name}).encode() + b"\n")
                buf = bytearray()
                pid = self.last_pid = json.loads(_recv_line(conn, buf))["pid"]
                conn.settimeout(timeout)
                try:
                    code = json.loads(_recv_line(conn, buf))["returncode"]
                except TimeoutError:
                    try:
                        os.killpg(pid, 9)
                    except ProcessLookupError:
                        pass
                    raise subprocess.TimeoutExpired(["twin", *args], timeout,
                                                    Path(out.name).read_bytes(), Path(err.name).read_bytes()) from None
            return subprocess.CompletedProcess(["twin", *args], code, Path(out.name).read_text(errors="replace"),
                                               Path(err.name).read_text(errors="replace"))
        finally:
            os.unlink(out.name)
            os.unlink(err.name)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.stdin.close()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        for name in os.listdir(self.dir):
            os.unlink(os.path.join(self.dir, name))
        os.rmdir(self.dir)


_SERVER: CallServer | None = None


def call(args: list[str], env: dict[str, str], cwd: Path,
         timeout: float | None = None) -> subprocess.CompletedProcess:
    """``python -m twin.cli ARGS`` in ``cwd`` with ``env``, forked from this test process's
    server: (args, exit code, standard output, standard error) as :func:`subprocess.run` with
    ``capture_output=True, text=True`` gives them."""
    global _SERVER
    if _SERVER is None or _SERVER.proc.poll() is not None:
        _SERVER = CallServer(cwd, env)
        atexit.register(_SERVER.close)
    return _SERVER.run(args, env, cwd, timeout)
