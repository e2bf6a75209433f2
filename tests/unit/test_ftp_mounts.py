"""FTP mounts: the flight-log directory served as `logs/` beside the FTP root, confined like it."""

from __future__ import annotations

import os

import pytest

from gcsd.vehicle.ftp.fs import ConfinedFs, DirEntry
from gcsd.vehicle.ftp.protocol import FtpError, Nak


@pytest.fixture
def fs(tmp_path):
    (tmp_path / "state" / "ftp").mkdir(parents=True)
    (tmp_path / "state" / "ftp" / "notes.txt").write_bytes(b"n")
    (tmp_path / "state" / "logs").mkdir()
    (tmp_path / "state" / "logs" / "00000001.BIN").write_bytes(b"\xa3\x95log")
    (tmp_path / "state" / "signing.key").write_bytes(b"SECRET")
    os.symlink("../signing.key", tmp_path / "state" / "logs" / "key_link")
    return ConfinedFs(tmp_path / "state" / "ftp", 1 << 20, {"logs": tmp_path / "state" / "logs"})


def test_the_root_lists_the_mount_as_a_directory(fs):
    assert fs.list_dir(b"/") == [DirEntry("logs", True, 0), DirEntry("notes.txt", False, 1)]


def test_files_under_the_mount_are_listed_and_read(fs):
    assert fs.list_dir(b"logs") == [DirEntry("00000001.BIN", False, 5)]  # key_link leaves: not listed
    f = fs.open_read(b"/logs/00000001.BIN")
    assert f.read(0, 100) == b"\xa3\x95log"
    f.close()


@pytest.mark.parametrize("path", [b"logs/../signing.key", b"logs/key_link", b"logs/../../state/signing.key"])
def test_nothing_beside_the_mount_is_reachable(fs, path):
    with pytest.raises(FtpError) as err:
        fs.open_read(path)
    assert err.value.code == Nak.FILE_NOT_FOUND


def test_the_mount_point_cannot_be_removed_or_renamed(fs):
    for op in (lambda: fs.remove_dir(b"logs"), lambda: fs.rename(b"logs", b"other")):
        with pytest.raises(FtpError) as err:
            op()
        assert err.value.code == Nak.FAIL
