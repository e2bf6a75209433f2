"""The control socket's requests (control.py): status by default, commands by name, and a command
that fails is answered as failed and counted, never left hanging."""

import asyncio
import json
import socket

from gcsd.api import control


def _ask(path, payload: bytes | None) -> dict:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(5)
        sock.connect(str(path))
        if payload is not None:
            sock.sendall(payload)
        sock.shutdown(socket.SHUT_WR)
        data = b""
        while chunk := sock.recv(65536):
            data += chunk
    return json.loads(data)


def test_status_commands_failures_and_nonsense(tmp_path):
    path = tmp_path / "gcsd.sock"
    failures = []

    async def add(request):
        return None if request["spec"] == "good" else "name: taken"

    async def broken(request):
        raise RuntimeError("boom")

    async def main():
        server = await control.serve(path, lambda: {"channels": []}, {"channel_add": add, "channel_remove": broken},
                                     failures.append)
        loop = asyncio.get_running_loop()
        try:
            ask = lambda payload: loop.run_in_executor(None, _ask, path, payload)
            assert await ask(None) == {"channels": []}  # a half-closed connection: status
            assert await ask(b'{"cmd": "status"}\n') == {"channels": []}
            assert await ask(b'{"cmd": "channel_add", "spec": "good"}\n') == {"ok": True, "error": None}
            assert await ask(b'{"cmd": "channel_add", "spec": "bad"}\n') == {"ok": False, "error": "name: taken"}
            failed = await ask(b'{"cmd": "channel_remove", "name": "x"}\n')
            assert failed["ok"] is False and "traceback" in failed["error"]
            assert (await ask(b"not json\n"))["ok"] is False
            assert (await ask(b'{"cmd": "reboot"}\n'))["error"] == "unknown request 'reboot'"
        finally:
            server.close()

    asyncio.run(main())
    assert failures == ["channel_remove"]


def test_the_socket_is_never_open_to_others_even_under_a_permissive_umask(tmp_path, monkeypatch):
    """Issue 26: on 63f9fa5 the socket was bound under the process's umask and chmod'ed 0600 after;
    under umask 000 it was srwxrwxrwx until then. Its mode is read at the chmod (the end of that
    window), under umask 000."""
    import os
    import stat

    path = tmp_path / "gcsd.sock"
    seen = []
    chmod = os.chmod

    def spy(target, mode, *args, **kw):
        if str(target) == str(path):
            seen.append(stat.S_IMODE(os.stat(target).st_mode))
        return chmod(target, mode, *args, **kw)

    monkeypatch.setattr(os, "chmod", spy)

    async def main():
        old = os.umask(0)
        try:
            server = await control.serve(path, lambda: {"channels": []})
        finally:
            os.umask(old)
        loop = asyncio.get_running_loop()
        try:
            assert await loop.run_in_executor(None, _ask, path, None) == {"channels": []}  # it serves
        finally:
            server.close()
        return old

    umask = asyncio.run(main())
    assert seen and seen[0] & 0o077 == 0, f"mode {seen[0]:o} before the chmod"
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    assert os.umask(umask) == umask  # the process's umask is put back
