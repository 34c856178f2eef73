"""Benchmark reports record what the results pages print above each table: the command
line, the machine and the date (crowdstudy.bench.write_report)."""

import json

from crowdstudy import bench


def test_write_report_records_command_machine_and_date(tmp_path):
    path = bench.write_report(
        "demo", [{"case": "a", "median_s": 0.5}], out=tmp_path / "demo.json", seed=3, participants=4
    )
    report = json.loads(path.read_text())
    assert report["benchmark"] == "demo" and report["rows"] == [{"case": "a", "median_s": 0.5}]
    assert report["participants"] == 4 and report["provenance"]["seed"] == 3
    assert isinstance(report["command"], str) and report["command"]
    machine = report["machine"]
    assert machine["cpu"] and machine["cores"] >= 1 and isinstance(machine["gpus"], list)
    assert machine["load_average"] is None or len(machine["load_average"]) == 3
    assert report["date"][:4].isdigit() and report["date"][4] == "-" and "T" in report["date"]


def test_the_command_is_the_bench_command_line(tmp_path, monkeypatch):
    seen = {}

    class Fake:
        @staticmethod
        def main(argv):
            seen["path"] = bench.write_report("fake", [], out=tmp_path / "fake.json")
            return 0

    monkeypatch.setattr(bench, "load_benchmark", lambda name: Fake)
    monkeypatch.setattr(bench, "report_path", lambda name: tmp_path / f"{name}.json")
    assert bench.run_benchmarks("fake", ["--agents", "60,1000", "--note", "two words"]) == 0
    report = json.loads(seen["path"].read_text())
    assert report["command"] == "crowdstudy bench fake --agents 60,1000 --note 'two words'"
    assert bench.command_line() != report["command"]  # reset once the benchmark returns


def test_a_benchmark_may_name_its_own_command(tmp_path):
    path = bench.write_report("x", [], out=tmp_path / "x.json", command="crowdstudy bench x --custom")
    assert json.loads(path.read_text())["command"] == "crowdstudy bench x --custom"
