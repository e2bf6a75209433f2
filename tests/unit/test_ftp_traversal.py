"""FTP confinement (SPEC.md FTP, CLIENTS.md "FTP escapes its root"): hostile paths and symlink
layouts, for every opcode that takes a path, are refused with FileNotFound/Fail (or
InvalidDataSize for a malformed path), and nothing outside the root is read, written, listed,
renamed or removed: every file and directory outside keeps its content and timestamps, no
reply carries an outside name or byte, and no file can be opened to read or write afterwards.

Layout (the root is `data`; `data2` and `data-evil` share its name as a prefix):

    tmp/secret.txt                 tmp/data2/secret.txt          tmp/data-evil/secret.txt
    tmp/outside/secret.txt         tmp/outside/OUTSIDE_NAME_MARKER/
    tmp/data/inside.txt            tmp/data/sub/deep.txt
    tmp/data/link_in -> sub/deep.txt                 (inside: allowed)
    tmp/data/link_out_file -> ../data2/secret.txt    (sibling with the root's prefix)
    tmp/data/link_out_dir -> ../outside
    tmp/data/link_abs -> /abs/path/to/outside/secret.txt
    tmp/data/link_chain -> link_out_dir              (a link to a link that leaves)
    tmp/data/link_parent -> ..
    tmp/data/dangling_out -> ../outside/created_by_ftp (does not exist: creating must not follow it)
    tmp/data/sub/link_up2 -> ../../data-evil
    tmp/data/link_loop -> link_loop
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from ftp_helpers import Gcs, is_ack, make_server, nak_code

from gcsd.vehicle.ftp.fs import ConfinedFs
from gcsd.vehicle.ftp.protocol import FtpError, Nak, Op

SECRET = b"TOP-SECRET-OUTSIDE-CONTENT"
MARKER = "OUTSIDE_NAME_MARKER"
REFUSED = {Nak.FILE_NOT_FOUND, Nak.FAIL, Nak.INVALID_DATA_SIZE}


@pytest.fixture
def layout(tmp_path):
    (tmp_path / "secret.txt").write_bytes(SECRET + b"-parent")
    for sibling in ("data2", "data-evil", "outside"):
        (tmp_path / sibling).mkdir()
        (tmp_path / sibling / "secret.txt").write_bytes(SECRET + sibling.encode())
    (tmp_path / "outside" / MARKER).mkdir()
    root = tmp_path / "data"
    (root / "sub").mkdir(parents=True)
    (root / "inside.txt").write_bytes(b"inside")
    (root / "sub" / "deep.txt").write_bytes(b"deep")
    os.symlink("sub/deep.txt", root / "link_in")
    os.symlink("../data2/secret.txt", root / "link_out_file")
    os.symlink("../outside", root / "link_out_dir")
    os.symlink(str(tmp_path / "outside" / "secret.txt"), root / "link_abs")
    os.symlink("link_out_dir", root / "link_chain")
    os.symlink("..", root / "link_parent")
    os.symlink("../outside/created_by_ftp", root / "dangling_out")
    os.symlink("../../data-evil", root / "sub" / "link_up2")
    os.symlink("link_loop", root / "link_loop")
    return tmp_path, root


def hostile_paths(tmp: Path) -> list[bytes]:
    outside_abs = str(tmp / "outside" / "secret.txt").encode()
    return [
        b"../secret.txt",
        b"/../secret.txt",
        b"./../secret.txt",
        b"sub/../../secret.txt",
        b"../data2/secret.txt",
        b"../data-evil/secret.txt",
        b"/" + b"../" * 12 + b"etc/passwd",
        outside_abs,  # an absolute path outside: mapped under the root, where it does not exist
        b"/etc/passwd",
        b"link_out_file",
        b"link_out_dir",
        b"link_out_dir/secret.txt",
        b"link_out_dir/" + MARKER.encode(),
        b"link_abs",
        b"link_chain/secret.txt",
        b"link_parent/secret.txt",
        b"link_parent/data2/secret.txt",
        b"link_parent",
        b"dangling_out",
        b"sub/link_up2/secret.txt",
        b"sub/link_up2",
        b"link_loop",
        b"link_out_dir/../secret.txt",
        b"@PARAM/../secret.txt",
        b"/@MISSION/../../secret.txt",
    ]


def snapshot(tmp: Path, root: Path) -> dict:
    """Everything outside the root (content, type, size, mtime, ctime) and the root's own links."""
    state = {}
    for dirpath, dirnames, filenames in os.walk(tmp, followlinks=False):
        here = Path(dirpath)
        if here == root or root in here.parents:
            continue
        for name in dirnames + filenames:
            p = here / name
            st = os.lstat(p)
            content = p.read_bytes() if p.is_file() and not p.is_symlink() else None
            state[str(p)] = (st.st_mode, st.st_size, st.st_mtime_ns, st.st_ctime_ns, content)
        st = os.lstat(here)
        state[str(here)] = (st.st_mode, st.st_mtime_ns, st.st_ctime_ns, tuple(sorted(os.listdir(here))))
    for p in root.rglob("*"):
        if p.is_symlink():
            state[str(p)] = ("link", os.readlink(p))
    return state


PATH_OPS = [Op.LIST_DIRECTORY, Op.OPEN_FILE_RO, Op.CREATE_FILE, Op.OPEN_FILE_WO, Op.REMOVE_FILE,
            Op.CREATE_DIRECTORY, Op.REMOVE_DIRECTORY, Op.TRUNCATE_FILE, Op.CALC_FILE_CRC32,
            "RENAME_FROM", "RENAME_TO"]


def _assert_clean(replies, tmp):
    for p in replies:
        assert SECRET not in p.data and MARKER.encode() not in p.data, p
        assert b"secret" not in p.data, p  # no outside name leaks into a listing either


@pytest.mark.parametrize("opcode", PATH_OPS, ids=lambda o: o if isinstance(o, str) else o.name)
def test_every_path_opcode_refuses_every_hostile_path_and_touches_nothing_outside(layout, opcode):
    tmp, root = layout
    gcs = Gcs(make_server(root))
    paths = hostile_paths(tmp)
    assert len(paths) >= 15
    before = snapshot(tmp, root)
    for path in paths:
        if opcode == "RENAME_FROM":
            reply = gcs.one(Op.RENAME, path + b"\0moved.txt")
        elif opcode == "RENAME_TO":
            reply = gcs.one(Op.RENAME, b"inside.txt\0" + path)
        else:
            reply = gcs.one(opcode, path, offset=0)
        assert nak_code(reply) in REFUSED, (path, reply)
        _assert_clean([reply], tmp)
        # nothing was left open to read from or write to
        for follow in (gcs.request(Op.READ_FILE, size=239), gcs.request(Op.WRITE_FILE, b"pwned"),
                       gcs.request(Op.BURST_READ_FILE, size=239) or gcs.pump()):
            assert all(nak_code(p) == Nak.FILE_NOT_FOUND for p in follow), (path, follow)
            _assert_clean(follow, tmp)
        gcs.one(Op.TERMINATE_SESSION)
        assert snapshot(tmp, root) == before, path
    assert (root / "inside.txt").read_bytes() == b"inside"
    assert not (tmp / "outside" / "created_by_ftp").exists()


def test_listing_the_root_leaves_out_links_that_lead_outside(layout):
    _tmp, root = layout
    gcs = Gcs(make_server(root))
    entries, offset = [], 0
    while True:
        reply = gcs.one(Op.LIST_DIRECTORY, b"/", offset=offset)
        if nak_code(reply) == Nak.EOF:
            break
        page = reply.data[:reply.size].split(b"\0")[:-1]
        entries += page
        offset += len(page)
    assert entries == [b"Finside.txt\t6", b"Flink_in\t4", b"Dsub"]


def test_links_that_stay_inside_work(layout):
    _tmp, root = layout
    gcs = Gcs(make_server(root))
    assert is_ack(gcs.one(Op.OPEN_FILE_RO, b"link_in"))
    assert gcs.one(Op.READ_FILE, size=10).data[:4] == b"deep"
    assert is_ack(gcs.one(Op.TERMINATE_SESSION))
    assert is_ack(gcs.one(Op.REMOVE_FILE, b"link_in"))
    assert not (root / "link_in").exists()
    assert (root / "sub" / "deep.txt").exists()  # the link went, not its target


def test_dot_dot_is_refused_even_when_it_would_stay_inside(layout):
    _tmp, root = layout
    gcs = Gcs(make_server(root))
    assert nak_code(gcs.one(Op.OPEN_FILE_RO, b"sub/../inside.txt")) == Nak.FILE_NOT_FOUND


def test_a_path_with_a_nul_inside_its_size_is_invalid_data_size(layout):
    _tmp, root = layout
    gcs = Gcs(make_server(root))
    assert nak_code(gcs.one(Op.OPEN_FILE_RO, b"inside.txt\0../secret.txt")) == Nak.INVALID_DATA_SIZE


def test_a_root_reached_through_a_symlink_is_confined_to_its_target(layout):
    tmp, root = layout
    os.symlink(root, tmp / "root_link")
    gcs = Gcs(make_server(tmp / "root_link"))
    assert is_ack(gcs.one(Op.OPEN_FILE_RO, b"inside.txt"))
    gcs.one(Op.TERMINATE_SESSION)
    assert nak_code(gcs.one(Op.OPEN_FILE_RO, b"link_out_file")) == Nak.FILE_NOT_FOUND


def test_confinement_compares_path_components_not_string_prefixes(layout):
    tmp, root = layout
    fs = ConfinedFs(root, 1000)
    assert fs.resolve(b"inside.txt") == root.resolve() / "inside.txt"
    for path in (b"link_out_file", b"../data2", b"../data-evil/secret.txt"):
        with pytest.raises(FtpError) as refused:
            fs.resolve(path)
        assert refused.value.code == Nak.FILE_NOT_FOUND
    assert str(tmp.resolve() / "data2").startswith(str(fs.root))  # the trap a string prefix falls into
