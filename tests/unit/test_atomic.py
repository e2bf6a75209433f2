import os

from gcsd.atomic import write_atomic


def test_write_atomic_replaces_content_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "state" / "mav.parm"
    write_atomic(target, "A 1\n")
    write_atomic(target, b"A 2\n")
    assert target.read_text() == "A 2\n"
    assert [p.name for p in target.parent.iterdir()] == ["mav.parm"]


def test_write_atomic_cleans_up_a_temporary_left_by_a_crash(tmp_path):
    (tmp_path / ".mav.parm.tmp-crash").write_text("torn")
    write_atomic(tmp_path / "mav.parm", "A 1\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mav.parm"]


def test_write_atomic_sets_the_requested_mode(tmp_path):
    write_atomic(tmp_path / "key", b"secret", mode=0o600)
    assert (os.stat(tmp_path / "key").st_mode & 0o777) == 0o600
