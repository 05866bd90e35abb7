"""The web viewer and its recording on one origin, so that a browser on another machine can read
both.

Rerun's web viewer page (HTTP) reads the recording from Rerun's gRPC server with gRPC-web calls;
that server answers cross-origin calls only from pages served by ``localhost`` or ``127.0.0.1``,
so a page opened at ``http://<this-host>:9090`` from another machine gets no data and shows
Rerun's welcome screen. :class:`OneOrigin` listens on the web port and forwards each request to
where it belongs: a gRPC-web call (a path under ``/rerun.``) to the gRPC server, anything else to
the web viewer's own server, both on this machine. The page then reads its data from its own
origin (``?url=rerun+http://<this-host>:9090/proxy``), with no cross-origin call at all.

Responses are streamed as they come (a live run's gRPC stream never ends): with their length
where the server gave one, else chunked.
"""

import http.client
import socket
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

GRPC_PREFIX = "/rerun."
"""The paths of Rerun's gRPC services (``/rerun.sdk_comms.v1alpha1.MessageProxyService/...``)."""

HOP_BY_HOP = {"connection", "keep-alive", "proxy-connection", "transfer-encoding", "te",
              "trailer", "upgrade", "host", "origin"}
"""Headers that belong to one connection, not to the request or response forwarded (and the
page's origin, which the servers on this machine need not judge)."""

UPSTREAM_TIMEOUT_S = 3600.0
"""How long a forwarded call may wait for the next bytes: a live run's stream idles between
episodes, and a viewer left open on a finished run idles for good."""


class OneOrigin:
    """An HTTP server on ``bind:port`` in front of the web viewer server (``viewer_port``) and
    the gRPC server (``grpc_port``), both on ``127.0.0.1``. Serves from a thread until
    :meth:`close`."""

    def __init__(self, bind: str, port: int, viewer_port: int, grpc_port: int) -> None:
        handler = type("Handler", (_Forward,), {"viewer_port": viewer_port,
                                                "grpc_port": grpc_port})
        family = socket.AF_INET6 if ":" in bind else socket.AF_INET
        server = type("Server", (ThreadingHTTPServer,), {"address_family": family})
        self.server = server((bind, port), handler)
        self.server.daemon_threads = True
        self.thread = threading.Thread(target=self.server.serve_forever, name="one-origin",
                                       daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


class _Forward(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"
    viewer_port: int
    grpc_port: int

    def log_message(self, format, *args) -> None:  # noqa: A002 - BaseHTTPRequestHandler's name
        pass  # one line per request would flood the launcher's terminal

    def forward(self) -> None:
        port = self.grpc_port if self.path.startswith(GRPC_PREFIX) else self.viewer_port
        length = int(self.headers.get("Content-Length") or 0)
        body = self.rfile.read(length) if length else None
        headers = {k: v for k, v in self.headers.items() if k.lower() not in HOP_BY_HOP}
        upstream = http.client.HTTPConnection("127.0.0.1", port, timeout=UPSTREAM_TIMEOUT_S)
        try:
            try:
                upstream.request(self.command, self.path, body=body, headers=headers)
                answer = upstream.getresponse()
            except OSError as error:
                self.send_error(502, f"nothing answers on port {port}: {error}")
                return
            self.send_response(answer.status, answer.reason)
            for key, value in answer.getheaders():
                if key.lower() not in HOP_BY_HOP:
                    self.send_header(key, value)
            sized = answer.getheader("Content-Length") is not None
            if not sized:
                self.send_header("Transfer-Encoding", "chunked")
            self.end_headers()
            if self.command != "HEAD":
                self.stream(answer, chunked=not sized)
        except (OSError, http.client.HTTPException):  # the browser went away, or the server did
            self.close_connection = True
        finally:
            upstream.close()

    def stream(self, answer: http.client.HTTPResponse, chunked: bool) -> None:
        while True:
            data = answer.read1(65536)
            if not data:
                break
            self.wfile.write(b"%x\r\n%s\r\n" % (len(data), data) if chunked else data)
            self.wfile.flush()
        if chunked:
            self.wfile.write(b"0\r\n\r\n")
            self.wfile.flush()

    do_GET = do_POST = do_HEAD = do_OPTIONS = forward
