"""Where the records of an MCAP file are (for damage tests), walked by hand."""
import struct


def opcode_offsets(data):
    """Byte offsets of every record opcode in the data section: top-level records (walked
    from the header to the summary start the footer gives) and the records inside each
    uncompressed chunk."""
    summary_start = struct.unpack_from('<Q', data, len(data) - 8 - 29 + 9)[0]
    offsets, pos = [], 8
    while pos < summary_start:
        op, length = struct.unpack_from('<BQ', data, pos)
        offsets.append(pos)
        if op == 0x06:
            body = pos + 9
            (clen,) = struct.unpack_from('<I', data, body + 28)
            records = body + 32 + clen + 8
            inner, end = records, pos + 9 + length
            while inner < end:
                offsets.append(inner)
                inner += 9 + struct.unpack_from('<Q', data, inner + 1)[0]
        pos += 9 + length
    return offsets
