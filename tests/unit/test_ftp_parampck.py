"""`@PARAM/param.pck` (REFERENCE.md 6.1): golden bytes derived by hand from the layout,
cross-checked with MAVProxy's own decoder (MAVProxy.modules.lib.param_ftp) as an independent
oracle; the padding rule, the fixed read size, the query, and uploads that set parameters."""

from __future__ import annotations

import errno
import random
import struct
from dataclasses import dataclass

import pytest
from ftp_helpers import Gcs, errno_of, is_ack, make_server, nak_code
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.ftp.parampck import PckQuery, decode_upload, encode, parse_query
from gcsd.vehicle.ftp.protocol import FtpError, Nak, Op
from gcsd.vehicle.ftp.virtual import VirtualFiles

param_ftp = pytest.importorskip("MAVProxy.modules.lib.param_ftp")

INT8, INT16, INT32, REAL32 = (M.MAV_PARAM_TYPE_INT8, M.MAV_PARAM_TYPE_INT16, M.MAV_PARAM_TYPE_INT32,
                              M.MAV_PARAM_TYPE_REAL32)
SIZE = {INT8: 1, INT16: 2, INT32: 4, REAL32: 4}
CODE = {INT8: 1, INT16: 2, INT32: 3, REAL32: 4}


@dataclass(frozen=True)
class P:
    name: str
    ptype: int
    value: float | int
    default: float | int


class FakeParams:
    """The ParamSource interface over a list, recording what an upload sets."""

    def __init__(self, params: list[P], read_only: frozenset[str] = frozenset()) -> None:
        self.params = params
        self.read_only = read_only
        self.set_calls: list[tuple[str, float]] = []
        self.commits = 0
        self.downloads = 0

    def entries(self):
        return iter(self.params)

    def count(self) -> int:
        return len(self.params)

    def set_from_file(self, name: str, value: float) -> bool:
        self.set_calls.append((name, value))
        return name not in self.read_only and any(p.name == name for p in self.params)

    def commit(self) -> None:
        self.commits += 1

    def downloaded(self) -> None:
        self.downloads += 1


SMALL = [
    P("ARMING_CHECK", INT8, 1, 0),
    P("ARMING_MIS_ITEMS", INT32, 0, 0),
    P("BATT_CAPACITY", INT32, 3300, 3300),
    P("RC1_MIN", INT16, 1100, 1100),
    P("ZZ", REAL32, 0.5, 0.25),
]

E1 = bytes([0x01, 0xB0]) + b"ARMING_CHECK" + b"\x01"  # INT8, 0 shared, 12-char tail
E2 = bytes([0x03, 0x87]) + b"MIS_ITEMS" + b"\x00\x00\x00\x00"  # INT32, "ARMING_" shared (7), 9-char tail
E3 = bytes([0x03, 0xC0]) + b"BATT_CAPACITY" + struct.pack("<i", 3300)
E4 = bytes([0x02, 0x60]) + b"RC1_MIN" + struct.pack("<h", 1100)
E5 = bytes([0x04, 0x10]) + b"ZZ" + struct.pack("<f", 0.5)


# --- golden bytes ----------------------------------------------------------------------------


def test_golden_file_without_defaults():
    assert encode(SMALL, 5) == struct.pack("<HHH", 0x671B, 5, 5) + E1 + E2 + E3 + E4 + E5


def test_golden_file_with_defaults_flags_only_values_that_differ():
    e1 = bytes([0x11, 0xB0]) + b"ARMING_CHECK" + b"\x01\x00"  # flag 1: default 0 follows
    e5 = bytes([0x14, 0x10]) + b"ZZ" + struct.pack("<ff", 0.5, 0.25)
    expected = struct.pack("<HHH", 0x671C, 5, 5) + e1 + E2 + E3 + E4 + e5
    assert encode(SMALL, 5, PckQuery(with_defaults=True)) == expected


def test_golden_padding_puts_a_value_that_would_straddle_a_block_at_the_boundary():
    # With 35-byte reads the INT32 of entry 2 would occupy bytes 32..35: 3 zero bytes move it to 35..38.
    assert encode(SMALL, 5, block=35) == (
        struct.pack("<HHH", 0x671B, 5, 5) + E1 + b"\0\0\0" + E2 + E3 + E4 + E5)


def test_golden_start_and_count_select_entries_and_set_num_params():
    data = encode(SMALL, 5, PckQuery(start=2, count=2))
    assert data == struct.pack("<HHH", 0x671B, 2, 5) + E3 + E4


def test_a_repeated_name_keeps_a_one_character_tail():
    data = encode([P("ABC", INT8, 1, 1), P("ABC", INT8, 2, 2)], 2)
    assert data[6:] == bytes([0x01, 0x20]) + b"ABC\x01" + bytes([0x01, 0x02]) + b"C\x02"


def test_sixteen_character_names_share_at_most_15():
    data = encode([P("SERVO10_FUNCTION", INT16, 1, 1), P("SERVO10_FUNCTIOX", INT16, 2, 2)], 2)
    assert data[6 + 2 + 16 + 2:][:3] == bytes([0x02, 0x0F]) + b"X"


def test_integer_values_are_twos_complement_in_their_own_size():
    data = encode([P("A", INT8, -1, -1), P("B", INT16, -300, 0), P("C", INT32, -(2**31), 0)], 3)
    assert data[6:] == bytes([1, 0]) + b"A\xff" + bytes([2, 0]) + b"B" + struct.pack("<h", -300) + \
        bytes([3, 0]) + b"C" + struct.pack("<i", -(2**31))


# --- MAVProxy's decoder as the oracle ---------------------------------------------------------


def _random_params(n: int, seed: int) -> list[P]:
    rng = random.Random(seed)
    prefixes = ["ARMING_", "BATT_", "BATT2_", "COMPASS_OFS", "RC", "SERVO", "SR0_", "SR1_", "INS_ACC",
                "Q_A_RAT_"]
    names = set()
    while len(names) < n:
        names.add((rng.choice(prefixes) + "".join(rng.choice("ABCDEFGHIJ_0123456789")
                                                  for _ in range(rng.randint(1, 9))))[:16])
    out = []
    for name in sorted(names):
        ptype = rng.choice([INT8, INT16, INT32, REAL32])
        if ptype == REAL32:
            value = struct.unpack("<f", struct.pack("<f", rng.uniform(-1e4, 1e4)))[0]
        else:
            bits = SIZE[ptype] * 8
            value = rng.randint(-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
        default = value if rng.random() < 0.7 else (value // 2 if ptype != REAL32 else value / 2)
        out.append(P(name, ptype, value, default))
    return out


@pytest.mark.parametrize("block", [239, 80, 110, 37, 7, 1])
@pytest.mark.parametrize("with_defaults", [False, True])
def test_mavproxy_decodes_1000_parameters_exactly(block, with_defaults):
    params = _random_params(1000, seed=block)
    data = encode(params, len(params), PckQuery(with_defaults=with_defaults), block)
    decoded = param_ftp.ftp_param_decode(data)
    assert decoded is not None
    assert [(n.decode(), t) for n, _, t in decoded.params] == [(p.name, CODE[p.ptype]) for p in params]
    assert [v for _, v, _ in decoded.params] == [p.value for p in params]
    if with_defaults:
        assert [v for _, v, _ in decoded.defaults] == [p.default for p in params]
    else:
        assert decoded.defaults is None


def _value_spans(data: bytes) -> list[list[tuple[int, int]]]:
    """Per entry, the (offset, size) of its value and default, found by walking the file."""
    spans, pos = [], 6
    with_defaults = struct.unpack_from("<H", data)[0] == 0x671C
    while pos < len(data):
        if data[pos] == 0:
            pos += 1
            continue
        code, flag = data[pos] & 0xF, data[pos] >> 4
        tail = (data[pos + 1] >> 4) + 1
        size = {1: 1, 2: 2, 3: 4, 4: 4}[code]
        start = pos + 2 + tail
        entry = [(start, size)] + ([(start + size, size)] if with_defaults and flag & 1 else [])
        spans.append(entry)
        pos = entry[-1][0] + size
    return spans


@pytest.mark.parametrize("block", [239, 80, 37, 10])
def test_no_value_straddles_a_read_block_boundary(block):
    data = encode(_random_params(500, seed=3), 500, block=block)
    for [(start, size)] in _value_spans(data):
        assert start // block == (start + size - 1) // block, (start, size)


@pytest.mark.parametrize("block", [239, 80, 37])
def test_with_defaults_the_last_value_of_an_entry_never_straddles_as_in_ardupilot(block):
    data = encode(_random_params(500, seed=4), 500, PckQuery(with_defaults=True), block)
    for spans in _value_spans(data):
        start, size = spans[-1]
        assert start // block == (start + size - 1) // block, (start, size)


# --- the query -------------------------------------------------------------------------------


@pytest.mark.parametrize("text,query", [
    ("", PckQuery()),
    ("withdefaults=1", PckQuery(with_defaults=True)),
    ("start=10&count=20", PckQuery(10, 20)),
    ("count=5&withdefaults=0&start=1", PckQuery(1, 5)),
    ("other=3&start=2", PckQuery(start=2)),
])
def test_query_is_parsed(text, query):
    assert parse_query(text) == query


@pytest.mark.parametrize("text", ["start=65535", "count=70000", "withdefaults=2", "start=-1", "start=x",
                                  "count"])
def test_bad_query_values_are_refused(text):
    assert parse_query(text) is None


# --- the virtual file through the server -----------------------------------------------------


@pytest.fixture
def params():
    return FakeParams(_random_params(300, seed=9))


@pytest.fixture
def gcs(tmp_path, params):
    return Gcs(make_server(tmp_path / "root", params=params))


def test_open_reports_the_exact_size_for_239_byte_reads_and_announces_the_download(gcs, params):
    reply = gcs.one(Op.OPEN_FILE_RO, b"@PARAM/param.pck?withdefaults=1")
    expected = encode(params.params, 300, PckQuery(with_defaults=True))
    assert int.from_bytes(reply.data[:4], "little") == len(expected)
    assert params.downloads == 1
    assert gcs.download(block=239) == expected


def test_a_leading_slash_before_the_virtual_root_is_ignored(gcs):
    assert is_ack(gcs.one(Op.OPEN_FILE_RO, b"/@PARAM/param.pck"))


def test_the_first_read_fixes_the_block_size_for_the_handle(gcs, params):
    gcs.one(Op.OPEN_FILE_RO, b"@PARAM/param.pck")
    expected = encode(params.params, 300, block=80)
    assert gcs.download(block=80) == expected
    assert gcs.one(Op.READ_FILE, size=80, offset=160).data[:80] == expected[160:240]
    reply = gcs.one(Op.READ_FILE, size=100, offset=160)
    assert errno_of(reply) == errno.EINVAL
    tail = len(expected) - 30
    assert gcs.one(Op.READ_FILE, size=100, offset=tail).data[:30] == expected[tail:]  # a short last read


def test_crc32_of_param_pck_does_not_announce_a_download(gcs, params):
    assert is_ack(gcs.one(Op.CALC_FILE_CRC32, b"@PARAM/param.pck"))
    assert params.downloads == 0


def test_listing_at_param_shows_param_pck(gcs):
    assert gcs.one(Op.LIST_DIRECTORY, b"@PARAM").data.startswith(b"Fparam.pck\t3600\0")


@pytest.mark.parametrize("name", [b"@PARAM/other.pck", b"@PARAM/param.pckx", b"@NOPE/param.pck", b"@PARAM"])
def test_other_virtual_names_are_file_not_found(gcs, name):
    assert nak_code(gcs.one(Op.OPEN_FILE_RO, name)) == Nak.FILE_NOT_FOUND


def test_start_beyond_the_last_parameter_is_einval(gcs):
    assert errno_of(gcs.one(Op.OPEN_FILE_RO, b"@PARAM/param.pck?start=300")) == errno.EINVAL


def test_at_most_four_param_files_are_open_at_once(tmp_path, params):
    server = make_server(tmp_path / "root", params=params)
    clients = [Gcs(server, sysid=200 + i) for i in range(5)]
    for c in clients[:4]:
        assert is_ack(c.one(Op.OPEN_FILE_RO, b"@PARAM/param.pck"))
    assert errno_of(clients[4].one(Op.OPEN_FILE_RO, b"@PARAM/param.pck")) == errno.ENFILE
    clients[0].one(Op.TERMINATE_SESSION)
    assert is_ack(clients[4].one(Op.OPEN_FILE_RO, b"@PARAM/param.pck"))


@pytest.mark.parametrize("op,data", [
    (Op.REMOVE_FILE, b"@PARAM/param.pck"), (Op.CREATE_DIRECTORY, b"@PARAM"),
    (Op.RENAME, b"@PARAM/param.pck\0x"), (Op.TRUNCATE_FILE, b"@PARAM/param.pck"),
])
def test_virtual_files_cannot_be_removed_renamed_or_truncated(gcs, op, data):
    assert nak_code(gcs.one(op, data)) == Nak.FILE_PROTECTED


# --- uploads ---------------------------------------------------------------------------------


def mavproxy_upload(values: dict[str, float]) -> bytes:
    """The file MAVProxy's `param ftpload` writes (mavproxy_param.ParamState.ftp_load)."""
    out, last = bytearray(struct.pack("<HHH", 0x671B, len(values), len(values))), ""
    for name in sorted(values):
        v = float(values[name])
        code = 4 if not v.is_integer() else 1 if -128 <= v <= 127 else 2 if -32768 <= v <= 32767 else 3
        shortest = min(len(last), len(name))
        common = next((i for i in range(shortest) if last[i] != name[i]), shortest)
        out += struct.pack("<BB", code, common | ((len(name) - (common + 1)) << 4)) + name[common:].encode()
        out += struct.pack({1: "<b", 2: "<h", 3: "<i", 4: "<f"}[code], v if code == 4 else int(v))
        last = name
    out[4:6] = struct.pack("<H", len(out))
    return bytes(out)


def test_decode_upload_reads_mavproxys_format():
    data = mavproxy_upload({"ARMING_CHECK": 0, "BATT_CAPACITY": 5000, "ZZ": 0.75, "RC1_MIN": -1000000})
    got = {(p.name, p.value) for p in decode_upload(data)}
    assert got == {("ARMING_CHECK", 0), ("BATT_CAPACITY", 5000), ("ZZ", 0.75), ("RC1_MIN", -1000000)}


@pytest.mark.parametrize("mangle", [
    lambda d: struct.pack("<H", 0x671C) + d[2:],  # the defaults magic
    lambda d: d[:4] + struct.pack("<H", len(d) + 1) + d[6:],  # total_params is not the length
    lambda d: d[:6] + bytes([d[6] | 0x10]) + d[7:],  # a flag
    lambda d: d[:-1],  # truncated
])
def test_malformed_uploads_are_refused_whole(mangle):
    assert decode_upload(mangle(mavproxy_upload({"ARMING_CHECK": 0, "BATT_CAPACITY": 5000}))) is None


def test_a_truncated_upload_is_refused_even_when_its_header_says_that_length():
    data = mavproxy_upload({"ARMING_CHECK": 0, "BATT_CAPACITY": 5000})[:-1]
    assert decode_upload(data[:4] + struct.pack("<H", len(data)) + data[6:]) is None


def test_uploading_param_pck_sets_parameters_when_the_session_ends(gcs, params):
    data = mavproxy_upload({"ARMING_CHECK": 3, "ZZ": 1.5})
    assert is_ack(gcs.one(Op.CREATE_FILE, b"@PARAM/param.pck"))
    for offset in range(0, len(data), 10):
        assert is_ack(gcs.one(Op.WRITE_FILE, data[offset:offset + 10], offset=offset))
    assert params.set_calls == []
    assert is_ack(gcs.one(Op.TERMINATE_SESSION))
    assert params.set_calls == [("ARMING_CHECK", 3), ("ZZ", 1.5)] and params.commits == 1


def test_a_malformed_upload_is_nakked_at_terminate_and_sets_nothing(gcs, params):
    assert is_ack(gcs.one(Op.CREATE_FILE, b"@PARAM/param.pck"))
    gcs.one(Op.WRITE_FILE, b"\x1c\x67\x01\x00\x08\x00\x01\x00", offset=0)
    reply = gcs.one(Op.TERMINATE_SESSION)
    assert errno_of(reply) == errno.EINVAL and params.set_calls == []


def test_an_upload_abandoned_until_the_idle_timeout_sets_nothing(gcs, params):
    data = mavproxy_upload({"ARMING_CHECK": 3})
    gcs.one(Op.CREATE_FILE, b"@PARAM/param.pck", now=0.0)
    gcs.one(Op.WRITE_FILE, data, now=0.0)
    gcs.server.expire(100.0)
    assert params.set_calls == []


def test_an_upload_larger_than_65535_bytes_is_einval(gcs):
    gcs.one(Op.CREATE_FILE, b"@PARAM/param.pck")
    assert errno_of(gcs.one(Op.WRITE_FILE, b"x" * 10, offset=65530)) == errno.EINVAL


def test_reader_refuses_writes_and_writer_refuses_reads(params):
    v = VirtualFiles(params)
    reader = v.open_read("@PARAM", "param.pck")
    with pytest.raises(FtpError):
        reader.write(0, b"x")
    writer = v.open_write("@PARAM", "param.pck")
    with pytest.raises(FtpError):
        writer.read(0, 10)
