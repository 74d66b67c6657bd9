"""The wire format of the participant protocol (docs/protocol.md): round trips, header
checks, NaN rejection, malformed payloads. Pure Python, no processes."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from coupler.protocol.errors import ProtocolError
from transfer import FieldError, TransferError
from coupler.protocol.wire import ALIGN, Field, check_reply, decode, decode_header, encode

HEADER = {"run_id": "r1", "participant": "solid", "verb": "advance", "window": 3, "iteration": 2}


@pytest.mark.parametrize("dtype", ["<f8", "<f4", "<i8", "<i4", "<u2", "|u1", "|i1", "|b1", "<c16", ">f8", ">i4"])
@pytest.mark.parametrize("shape", [(), (0,), (5,), (4, 3), (2, 0, 3), (2, 3, 4)])
def test_round_trip_dtypes_and_shapes(dtype, shape):
    rng = np.random.default_rng(1)
    data = np.asarray(rng.random(shape) * 100).astype(dtype)
    header, fields = decode(encode(HEADER, [Field("x", data, "m/s")]))
    out = fields["x"]
    assert out.data.dtype == np.dtype(dtype)
    assert out.data.shape == shape
    assert out.units == "m/s"
    np.testing.assert_array_equal(out.data, data)
    assert {k: header[k] for k in HEADER} == HEADER


def test_zero_d_stays_zero_d():
    _, fields = decode(encode({}, {"s": np.float64(2.5), "i": np.array(7)}))
    assert fields["s"].data.shape == () and fields["s"].data[()] == 2.5
    assert fields["i"].data.shape == () and fields["i"].data[()] == 7


def test_several_fields_keep_order_units_and_alignment():
    a = np.arange(7, dtype=np.float64)
    b = np.arange(12, dtype=np.int32).reshape(3, 4)
    c = np.zeros((0, 3))
    payload = encode(HEADER, [Field("a", a, "Pa"), Field("b", b), Field("c", c, "m")])
    header, fields = decode(bytes(payload))
    assert list(fields) == ["a", "b", "c"]
    assert [d["units"] for d in header["arrays"]] == ["Pa", "", "m"]
    (n,) = struct.unpack_from("<Q", payload, 0)
    start = -(-(8 + n) // ALIGN) * ALIGN
    for d in header["arrays"]:
        assert d["offset"] % ALIGN == 0 and (start + d["offset"]) % ALIGN == 0
    np.testing.assert_array_equal(fields["a"].data, a)
    np.testing.assert_array_equal(fields["b"].data, b)
    assert fields["c"].data.shape == (0, 3)


def test_decode_is_zero_copy():
    a = np.linspace(0, 1, 1000)
    payload = bytes(encode({}, {"a": a}))
    _, fields = decode(payload)
    view = fields["a"].data
    assert not view.flags.owndata and not view.flags.writeable  # a view of the bytes
    assert view.base is not None
    # From a bytearray the views are writable views of that buffer.
    buf = encode({}, {"a": a})
    _, fields = decode(buf)
    fields["a"].data[0] = 42.0
    assert decode(buf)[1]["a"].data[0] == 42.0


def test_non_contiguous_and_mapping_input():
    a = np.arange(24.0).reshape(4, 6)[:, ::2]
    _, fields = decode(encode({}, {"a": a, "b": Field("b", a.T, "K")}))
    np.testing.assert_array_equal(fields["a"].data, a)
    np.testing.assert_array_equal(fields["b"].data, a.T)
    assert fields["b"].units == "K"


def test_empty_message():
    header, fields = decode(encode({"verb": "finish"}))
    assert header["verb"] == "finish" and header["arrays"] == [] and fields == {}


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_and_inf_rejected_naming_the_field(bad):
    data = np.ones((10, 3))
    data[4, 1] = bad
    with pytest.raises(FieldError, match="traction") as info:
        encode(HEADER, [Field("ok", np.ones(3)), Field("traction", data)])
    assert info.value.field == "traction"
    assert "non-finite" in str(info.value) and "13" in str(info.value)  # flat index 4*3+1
    # the project's one FieldError: a field the transfer or the wire cannot use
    assert isinstance(info.value, TransferError) and isinstance(info.value, ValueError)


def test_nan_in_complex_and_float32_rejected_ints_fine():
    with pytest.raises(FieldError, match="'z'"):
        encode({}, {"z": np.array([1 + 1j, complex(0, np.nan)])})
    with pytest.raises(FieldError, match="'f'"):
        encode({}, {"f": np.array([np.float32("nan")])})
    encode({}, {"i": np.array([2**62, -5])})  # no finiteness for integers
    encode({}, {"e": np.zeros(0)})  # empty float arrays are fine
    # the check can be turned off (e.g. to send a diagnostic field on purpose)
    _, f = decode(encode({}, {"n": np.array([np.nan])}, check=False))
    assert np.isnan(f["n"].data[0])


@pytest.mark.parametrize("data", [np.array(["a", "b"]), np.array([object()], dtype=object),
                                  np.zeros(2, dtype=[("x", "f8")])])
def test_non_numeric_dtypes_rejected(data):
    with pytest.raises(FieldError, match="cannot travel"):
        encode({}, {"x": data})


def test_bad_names_and_headers():
    with pytest.raises(FieldError, match="twice"):
        encode({}, [Field("a", np.ones(1)), Field("a", np.ones(1))])
    with pytest.raises(FieldError, match="non-empty"):
        encode({}, [Field("", np.ones(1))])
    with pytest.raises(ProtocolError, match="reserved"):
        encode({"arrays": []})
    with pytest.raises(ProtocolError, match="JSON"):
        encode({"x": object()})
    with pytest.raises(ProtocolError, match="JSON"):
        encode({"t": float("nan")})


def test_malformed_payloads_rejected():
    good = bytes(encode(HEADER, {"a": np.arange(100.0)}))
    with pytest.raises(ProtocolError, match="truncated"):
        decode(good[:5])
    with pytest.raises(ProtocolError, match="truncated"):
        decode(good[:20])
    with pytest.raises(ProtocolError, match="truncated"):
        decode(good[:-8])
    with pytest.raises(ProtocolError, match="malformed"):
        decode(struct.pack("<Q", 3) + b"{x}")
    hdr = json.dumps({"arrays": [{"name": "a", "dtype": "<f8", "shape": [3], "offset": 0, "nbytes": 16}]}).encode()
    with pytest.raises(ProtocolError, match="does not make"):
        decode(struct.pack("<Q", len(hdr)) + hdr + bytes(64))
    hdr = json.dumps({"arrays": [{"name": "a", "dtype": "|O", "shape": [1], "offset": 0, "nbytes": 8}]}).encode()
    with pytest.raises(ProtocolError, match="not allowed"):
        decode(struct.pack("<Q", len(hdr)) + hdr + bytes(64))
    hdr = json.dumps({"v": 99}).encode()
    with pytest.raises(ProtocolError, match="version"):
        decode_header(struct.pack("<Q", len(hdr)) + hdr)


def test_check_reply_accepts_matching_reply():
    reply = dict(HEADER, elapsed=0.1, arrays=[])
    check_reply(HEADER, reply)
    # keys absent from the request are not compared
    check_reply({"run_id": "r1", "participant": "solid", "verb": "announce"},
                {"run_id": "r1", "participant": "solid", "verb": "announce", "kind": "x"})


@pytest.mark.parametrize("key,value", [("window", 2), ("iteration", 1), ("iteration", 3), ("run_id", "r0"),
                                       ("participant", "fluid"), ("verb", "geometry")])
def test_check_reply_rejects_stale_or_mismatched(key, value):
    reply = dict(HEADER)
    reply[key] = value
    with pytest.raises(ProtocolError, match=f"{key} is {value!r}, expected"):
        check_reply(HEADER, reply)


def test_check_reply_rejects_missing_keys():
    reply = dict(HEADER)
    del reply["iteration"]
    with pytest.raises(ProtocolError, match="has no 'iteration'"):
        check_reply(HEADER, reply)


def test_decoded_header_round_trip_through_check():
    _, _ = decode(encode(HEADER))
    header, _ = decode(encode(dict(HEADER, window=4)))
    with pytest.raises(ProtocolError, match="stale"):
        check_reply(HEADER, header)
