"""Reads a pa10d recording with the `mcap` Python package (a reader we did not write) and
prints what it found as JSON: messages per channel, whether log times never go back, the
schemas (name, encoding) and the cycle stamps' first and last values.

    python3 tests/record/check_mcap.py FILE.mcap
"""
import json
import sys

from mcap.reader import make_reader


def main(path: str) -> None:
    counts: dict[str, int] = {}
    schemas: dict[str, list[str]] = {}
    monotonic = True
    last = -1
    first_stamp = None
    last_stamp = None
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if schema is not None:
                schemas[channel.topic] = [schema.name, schema.encoding]
            if message.log_time < last:
                monotonic = False
            last = message.log_time
            if channel.topic == "/pa10/cycle":
                stamp = json.loads(message.data)["stamp_s"]
                first_stamp = stamp if first_stamp is None else first_stamp
                last_stamp = stamp
    print(json.dumps({"counts": counts, "monotonic": monotonic, "schemas": schemas,
                      "first_stamp": first_stamp, "last_stamp": last_stamp}))


if __name__ == "__main__":
    main(sys.argv[1])
