"""The machine description benchmarks record: a JSON-ready dict and one line for headings."""

import json
import os

from dtradar_data.core.machine import describe, machine


def test_the_machine_is_described_as_json_and_in_one_line():
    m = machine()
    assert json.loads(json.dumps(m)) == m
    assert m["cores"] == os.cpu_count() and m["cpu"] and m["python"] and m["platform"]
    assert m["load_average"] is None or len(m["load_average"]) == 3
    line = describe(m)
    assert "\n" not in line and line.startswith(m["cpu"]) and f"{m['cores']} cores" in line


def test_the_line_says_what_is_known_and_no_more():
    m = {
        "cpu": "Some CPU",
        "cores": 16,
        "usable_cores": 4,
        "load_average": [1.31, 1.06, 0.9],
        "memory_bytes": 8 * 2**30,
    }
    assert describe(m) == "Some CPU, 4 of 16 cores, 8.0 GiB, load 1.3 / 1.1 / 0.9"
    assert describe({"cpu": "Some CPU", "cores": 2}) == "Some CPU, 2 cores"
