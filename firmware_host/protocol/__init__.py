"""The joint-stream wire protocol: messages, encoder, streaming decoder (spec: docs/protocol.md)."""
from firmware_host.protocol.constants import (
    ALL_SCENE_FLAGS,
    MAX_FRAME_LEN,
    MAX_JOINTS,
    MAX_PACKET_LEN,
    PROTOCOL_VERSION,
    SCENE_FLAGS,
    CoordFrame,
    Fault,
    Flags,
    JointSet,
    MsgType,
    Units,
    hello_scene_flags,
)
from firmware_host.protocol.crc import crc16
from firmware_host.protocol.decoder import DecodeEvent, DecoderStats, StreamDecoder, decode_stream, parse_packet
from firmware_host.protocol.encoder import encode, encode_packet, frame_packet, joints_packet_len, wire_len
from firmware_host.protocol.from_frame import joints2d_messages, joints_message
from firmware_host.protocol.messages import Header, Hello, JointFrame, Joints, Joints2D, Message, Status, make_header

__all__ = [
    "MAX_FRAME_LEN", "MAX_JOINTS", "MAX_PACKET_LEN", "PROTOCOL_VERSION", "SCENE_FLAGS", "ALL_SCENE_FLAGS",
    "hello_scene_flags",
    "CoordFrame", "Fault", "Flags", "JointSet", "MsgType", "Units",
    "crc16", "DecodeEvent", "DecoderStats", "StreamDecoder", "decode_stream", "parse_packet",
    "encode", "encode_packet", "frame_packet", "joints_packet_len", "wire_len",
    "joints2d_messages", "joints_message",
    "Header", "Hello", "JointFrame", "Joints", "Joints2D", "Message", "Status", "make_header",
]
