#!/usr/bin/env python3
"""Decode a candump log with cantools and docs/pa10.dbc; compare with the values our codec
produced (a JSON list of {"id": int, "signals": {name: value}}, one per log line).

    python3 tests/dbc/check_dbc.py docs/pa10.dbc capture.log expected.json
    python3 tests/dbc/check_dbc.py docs/pa10-fd.dbc capture-fd.log expected.json

CAN FD frames (`ID##FDATA`) must be FD messages in the DBC, classic ones classic.

Exit 0 when every frame decodes to the same values (1e-9 relative), 1 with the differences
otherwise, 3 when cantools is not installed.
"""
import json
import sys

try:
    import cantools
except ImportError:
    print("cantools is not installed (pip install cantools)", file=sys.stderr)
    sys.exit(3)


def main():
    dbc, log, expected = sys.argv[1:4]
    db = cantools.database.load_file(dbc)
    want = json.load(open(expected))
    lines = [l for l in open(log).read().splitlines() if l.strip()]
    if len(lines) != len(want):
        print(f"{len(lines)} frames in the log, {len(want)} expected", file=sys.stderr)
        return 1
    bad = 0
    for line, exp in zip(lines, want):
        frame = line.split()[2]
        ident, data = frame.split("#", 1)
        if data.startswith("#"):
            # CAN FD (candump's ID##FDATA): one hex digit of flags, then the data
            data = data[2:]
        msg = db.get_message_by_frame_id(int(ident, 16))
        if msg.is_fd != (frame.count("#") == 2):
            print(f"{line}: the DBC has {msg.name} as {'an FD' if msg.is_fd else 'a classic'} frame", file=sys.stderr)
            bad += 1
            continue
        got = db.decode_message(int(ident, 16), bytes.fromhex(data), decode_choices=False)
        for name, value in exp["signals"].items():
            g = got.get(name)
            if g is None or abs(g - value) > 1e-9 * max(1.0, abs(value)):
                print(f"{line}: {name} = {g} (cantools) vs {value} (pa10 codec)", file=sys.stderr)
                bad += 1
        extra = set(got) - set(exp["signals"])
        if extra:
            print(f"{line}: cantools decodes signals the codec does not: {sorted(extra)}", file=sys.stderr)
            bad += 1
    print(f"{len(lines)} frames checked, {bad} differences")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
