"""MELFA real-time external control ("MXT") packet codec: the 196-byte UDP datagram, both directions (pure).

Wire contract shared by the arm bridge (``nodes/arm_bridge/mxt_link.py``, the client) and the controller twin
(``flexsheet/twin/mxt_server.py``, the server). Protocol facts and their sources:
``design/mxt_protocol.md``; the public struct is ``MXTCMD`` in tork-a/melfa_robot
``melfa_driver/include/melfa_driver/strdef.h`` (TORK, Apache-2.0) and ``MXTCMD`` in Mitsubishi-Electric-Asia/
melfa_ros2_driver ``melfa_driver/include/melfa_driver/rt_exc_def.hpp``. Both rely on natural alignment (no
``#pragma pack``): compiled on x86-64 they give 196 bytes and the offsets below. Each datagram is one struct,
no header, no checksum. Byte order: **little-endian** (every public client sends the raw x86 struct without
``hton*``; an inference, not a stated fact). Floats are IEEE-754 single precision.

=====  ====  ==========  ==========  =====================================================================
off    size  C type      field       meaning
=====  ====  ==========  ==========  =====================================================================
0      2     uint16      Command     ``CMD_NULL`` 0 (exchange data only) / ``CMD_MOVE`` 1 / ``CMD_END`` 255
2      2     uint16      SendType    type of ``dat`` when commanding (``TYP_POSE``/``TYP_JOINT``/``TYP_PULSE``)
4      2     uint16      RecvType    monitor type wanted in (request) / carried by (reply) slot 0
6      2     —           (pad)       implicit padding in strdef.h, ``reserve`` in rt_exc_def.hpp
8      40    union       dat         command (PC→RC) or monitor slot 0 (RC→PC)
48     2     uint16      SendIOType  I/O type written (``IO_OUT``); in a reply the type reported
50     2     uint16      RecvIOType  I/O type the PC wants reported (``IO_IN``/``IO_OUT``)
52     2     uint16      BitTop      first signal number of the 16-bit window
54     2     uint16      BitMask     which of the 16 output bits to write
56     2     uint16      IoData      16 signal bits
58     2     uint16      TCount      timeout counter (reply; meaning unconfirmed)
60     4     uint32      CCount      communication counter (the PC numbers its packets)
64     2     uint16      RecvType1   monitor type of slot 1
66     2     —           (pad)
68     40    union       dat1        monitor slot 1
108    2     uint16      RecvType2   monitor type of slot 2
110    2     —           (pad)
112    40    union       dat2        monitor slot 2
152    2     uint16      RecvType3   monitor type of slot 3
154    2     —           (pad)
156    40    union       dat3        monitor slot 3
=====  ====  ==========  ==========  =====================================================================

The 40-byte union has three views: JOINT ``float j1..j8`` (rad for rotary axes; j7, j8 the additional axes;
last 8 bytes unused), POSE ``float x, y, z`` (mm), ``a, b, c`` (rad), ``l1, l2``, ``uint32 sflg1, sflg2``,
and PULSE ``int32 p1..p8`` (also the current types, %). Unused axes are sent as 0.

Functions raise ``ValueError`` naming the field and the value on anything that does not fit the wire (wrong
length, unknown command or type code, non-finite or float32-overflowing joints, counters out of range).
"""  # noqa: E501 - a table, template or command line kept whole

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "SIZE", "PACKET", "JOINT_VIEW", "POSE_VIEW", "PULSE_VIEW", "DEFAULT_PORT",
    "CMD_NULL", "CMD_MOVE", "CMD_END", "COMMANDS",
    "TYP_NULL", "TYP_POSE", "TYP_JOINT", "TYP_PULSE", "TYP_FPOSE", "TYP_FJOINT", "TYP_FPULSE", "TYP_FB_POSE",
    "TYP_FB_JOINT", "TYP_FB_PULSE", "TYP_CMDCUR", "TYP_FBKCUR", "TYPE_NAMES",
    "IO_NULL", "IO_OUT", "IO_IN",
    "Packet", "encode_joint_data", "decode_joint_data", "null_packet", "move_packet", "end_packet",
]

DEFAULT_PORT = 10000            #: controller UDP port (T melfa_hardware_interface.cpp:38, M, R)

CMD_NULL = 0                    #: no motion command, exchange data only
CMD_MOVE = 1                    #: ``dat`` is this cycle's target
CMD_END = 255                   #: leave real-time external control (the ``Mxt`` instruction ends)
COMMANDS = (CMD_NULL, CMD_MOVE, CMD_END)

TYP_NULL = 0
TYP_POSE = 1                    #: XYZ command value
TYP_JOINT = 2                   #: joint command value
TYP_PULSE = 3                   #: pulse command value
TYP_FPOSE = 4                   #: XYZ after the controller's filter
TYP_FJOINT = 5                  #: joint after the controller's filter
TYP_FPULSE = 6                  #: pulse after the controller's filter
TYP_FB_POSE = 7                 #: XYZ from encoder feedback
TYP_FB_JOINT = 8                #: joint from encoder feedback
TYP_FB_PULSE = 9                #: pulse from encoder feedback
TYP_CMDCUR = 10                 #: current command, %
TYP_FBKCUR = 11                 #: current feedback, %
TYPE_NAMES = {TYP_NULL: "NULL", TYP_POSE: "POSE", TYP_JOINT: "JOINT", TYP_PULSE: "PULSE", TYP_FPOSE: "FPOSE",
              TYP_FJOINT: "FJOINT", TYP_FPULSE: "FPULSE", TYP_FB_POSE: "FB_POSE", TYP_FB_JOINT: "FB_JOINT",
              TYP_FB_PULSE: "FB_PULSE", TYP_CMDCUR: "CMDCUR", TYP_FBKCUR: "FBKCUR"}

IO_NULL = 0
IO_OUT = 1
IO_IN = 2

#: the whole datagram; ``x`` bytes are the alignment gaps (written as zero, ignored when read)
PACKET = struct.Struct("<HHH2x40sHHHHHHIH2x40sH2x40sH2x40s")
SIZE = PACKET.size              #: 196 bytes
JOINT_VIEW = struct.Struct("<8f8x")     #: union as JOINT: j1..j8 float32, 8 unused bytes
POSE_VIEW = struct.Struct("<8fII")      #: union as POSE: x, y, z mm, a, b, c rad, l1, l2, sflg1, sflg2
PULSE_VIEW = struct.Struct("<8i8x")     #: union as PULSE / integer view: p1..p8 int32
assert SIZE == 196 and JOINT_VIEW.size == POSE_VIEW.size == PULSE_VIEW.size == 40

_ZERO = bytes(40)
_F32_MAX = 3.4028234663852886e38


def _u(name: str, value, bits: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"MXT {name} must be an unsigned {bits}-bit int, got {value!r}")
    v = int(value)
    if not 0 <= v < (1 << bits):
        raise ValueError(f"MXT {name} must be in 0..{(1 << bits) - 1}, got {v}")
    return v


def _type(name: str, value) -> int:
    v = _u(name, value, 16)
    if v not in TYPE_NAMES:
        raise ValueError(f"MXT {name}={v} is not a data type code (0..11)")
    return v


def encode_joint_data(q, name: str = "dat") -> bytes:
    """JOINT view: (≤ 8,) joint values (rad; linear axes mm) → the 40-byte union, missing axes as 0.

    Raises ``ValueError`` naming ``name`` if ``q`` is not a 1-D vector of ≤ 8 finite values that fit float32.
    """
    a = np.asarray(q, dtype=float) if not isinstance(q, (str, bytes)) else None
    if a is None or a.ndim != 1 or not 1 <= a.size <= 8:
        raise ValueError(f"MXT {name}: joints must be a 1-D vector of 1..8 values, got {q!r}")
    bad = np.flatnonzero(~np.isfinite(a) | (np.abs(a) > _F32_MAX))
    if bad.size:
        k = int(bad[0])
        raise ValueError(f"MXT {name}.j{k + 1} must be finite (float32), got {a[k]!r}")
    vals = [0.0] * 8
    vals[:a.size] = a.tolist()
    return JOINT_VIEW.pack(*vals)


def decode_joint_data(raw: bytes, n: int = 6) -> np.ndarray:
    """The 40-byte union read as JOINT → the first ``n`` joints, (n,) float64 (rad). ``ValueError`` if not 40
    bytes."""
    if not isinstance(raw, (bytes, bytearray, memoryview)) or len(raw) != 40:
        raise ValueError(f"MXT union must be 40 bytes, got {type(raw).__name__} of length "
                         f"{len(raw) if hasattr(raw, '__len__') else '?'}")
    if not 1 <= n <= 8:
        raise ValueError(f"n must be 1..8 joints, got {n!r}")
    return np.array(JOINT_VIEW.unpack(bytes(raw))[:n], dtype=float)


@dataclass
class Packet:
    """One MXT datagram (the ``MXTCMD`` struct), request or reply.

    ``command``: ``CMD_*``. ``send_type``: type of ``data[0]`` when commanding. ``recv_types``: the four
    monitor types (RecvType, RecvType1..3). ``data``: the four 40-byte unions (dat, dat1..3).
    ``send_io_type``, ``recv_io_type``, ``bit_top``, ``bit_mask``, ``io_data``: the I/O window. ``tcount``:
    uint16; ``ccount``: uint32 communication counter.
    """

    command: int = CMD_NULL
    send_type: int = TYP_NULL
    recv_types: tuple[int, int, int, int] = (TYP_NULL, TYP_NULL, TYP_NULL, TYP_NULL)
    data: tuple[bytes, bytes, bytes, bytes] = field(default_factory=lambda: (_ZERO, _ZERO, _ZERO, _ZERO))
    send_io_type: int = IO_NULL
    recv_io_type: int = IO_NULL
    bit_top: int = 0
    bit_mask: int = 0
    io_data: int = 0
    tcount: int = 0
    ccount: int = 0

    def check(self) -> Packet:
        """Validate every field (see module doc); returns self. Raises ``ValueError`` naming the field."""
        c = _u("Command", self.command, 16)
        if c not in COMMANDS:
            raise ValueError(f"MXT Command={c} is not NULL (0), MOVE (1) or END (255)")
        _type("SendType", self.send_type)
        if len(self.recv_types) != 4 or len(self.data) != 4:
            raise ValueError(f"MXT packet needs 4 monitor slots, got {len(self.recv_types)} types and "
                             f"{len(self.data)} data blocks")
        for i, t in enumerate(self.recv_types):
            _type("RecvType" + (str(i) if i else ""), t)
        for i, d in enumerate(self.data):
            if not isinstance(d, (bytes, bytearray)) or len(d) != 40:
                raise ValueError(f"MXT dat{i or ''} must be 40 bytes, got "
                                 f"{len(d) if hasattr(d, '__len__') else d!r}")
        for name, v in (("SendIOType", self.send_io_type), ("RecvIOType", self.recv_io_type),
                        ("BitTop", self.bit_top), ("BitMask", self.bit_mask), ("IoData", self.io_data),
                        ("TCount", self.tcount)):
            _u(name, v, 16)
        _u("CCount", self.ccount, 32)
        return self

    def encode(self) -> bytes:
        """The 196-byte datagram. Raises ``ValueError`` naming the bad field."""
        self.check()
        r, d = self.recv_types, self.data
        return PACKET.pack(self.command, self.send_type, r[0], bytes(d[0]), self.send_io_type,
                           self.recv_io_type,
                           self.bit_top, self.bit_mask, self.io_data, self.tcount, self.ccount,
                           r[1], bytes(d[1]), r[2], bytes(d[2]), r[3], bytes(d[3]))

    @classmethod
    def decode(cls, buf: bytes) -> Packet:
        """Parse one datagram. Raises ``ValueError`` on a wrong length, an unknown command or type code."""
        if not isinstance(buf, (bytes, bytearray, memoryview)):
            raise ValueError(f"MXT datagram must be bytes, got {type(buf).__name__}")
        if len(buf) != SIZE:
            raise ValueError(f"MXT datagram must be {SIZE} bytes, got {len(buf)}")
        (cmd, st, r0, d0, sio, rio, top, mask, io, tc, cc, r1, d1, r2, d2, r3, d3) = PACKET.unpack(bytes(buf))
        return cls(cmd, st, (r0, r1, r2, r3), (d0, d1, d2, d3), sio, rio, top, mask, io, tc, cc).check()

    def slot_of(self, typ: int) -> int | None:
        """Index 0..3 of the first monitor slot holding type ``typ``, or None."""
        for i, t in enumerate(self.recv_types):
            if t == typ:
                return i
        return None

    def joints(self, typ: int, n: int = 6) -> np.ndarray | None:
        """The joints (n,) rad of the first slot whose type is ``typ`` (e.g. ``TYP_FB_JOINT``), or None."""
        i = self.slot_of(typ)
        return None if i is None else decode_joint_data(self.data[i], n)

    def command_joints(self, n: int = 6) -> np.ndarray:
        """The MOVE target ``dat`` read as JOINT, (n,) rad. ``ValueError`` if SendType is not JOINT."""
        if self.send_type != TYP_JOINT:
            raise ValueError(f"MXT SendType={self.send_type} ({TYPE_NAMES.get(self.send_type, '?')}) is not "
                             f"JOINT ({TYP_JOINT})")
        return decode_joint_data(self.data[0], n)


def null_packet(ccount: int = 0, recv_types=(TYP_JOINT, TYP_FB_JOINT, TYP_NULL, TYP_NULL)) -> Packet:
    """The opening (or keep-alive) packet: Command NULL, SendType NULL, the monitor types to read back."""
    return Packet(CMD_NULL, TYP_NULL, tuple(recv_types), ccount=ccount).check()


def move_packet(q, ccount: int, recv_types=(TYP_JOINT, TYP_FB_JOINT, TYP_NULL, TYP_NULL)) -> Packet:
    """A MOVE in joint type: ``q`` (≤ 8,) rad in ``dat`` (unused axes 0). ``ValueError`` on bad
    joints/counter."""
    return Packet(CMD_MOVE, TYP_JOINT, tuple(recv_types), (encode_joint_data(q), _ZERO, _ZERO, _ZERO),
                  ccount=ccount).check()


def end_packet(ccount: int) -> Packet:
    """Command END: the controller leaves real-time external control and its program goes on."""
    return Packet(CMD_END, TYP_NULL, ccount=ccount).check()

