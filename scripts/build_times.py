#!/usr/bin/env python3
"""Where a build's time went, from Ninja's log: the seconds of every step, summed by kind.

Usage: build_times.py [BUILD_DIR] [--top N]   (default: build, 15)

Reads BUILD_DIR/.ninja_log (the last run of each output) and prints the seconds spent compiling
libraries and tools, tests, benchmarks and generated protobuf/gRPC code, and linking, then the N
slowest steps. A step's seconds are its wall time: on a machine doing nothing else, with one job
a core (ninja -jN, N cores), their sum is the build's CPU-seconds.
"""
import argparse
import collections
import os


def kind(output):
    if output.endswith(".o"):
        if "/proto/" in output and (".pb." in output or ".grpc." in output):
            return "generated protobuf/gRPC code"
        if output.startswith("bench/") or "/bench_" in output:
            return "benchmark objects"
        if "_test" in output or "/testing/" in output:
            return "test objects"
        return "library and tool objects"
    if output.startswith(("bin/", "tests/")) or output.endswith((".a", ".so")):
        return "links and archives"
    return "other steps"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("build_dir", nargs="?", default="build")
    parser.add_argument("--top", type=int, default=15)
    args = parser.parse_args()
    # The last run of each output. A step with several outputs (a link and its gtest discovery
    # files) has a line per output, all with the step's command hash: it counts once, under the
    # output that says most of what it is (the binary rather than its discovery files).
    runs = {}
    with open(os.path.join(args.build_dir, ".ninja_log")) as log:
        for line in log:
            fields = line.rstrip("\n").split("\t")
            if line.startswith("#") or len(fields) < 5:
                continue
            start, end, _, output, command_hash = fields
            runs[output] = (command_hash, (int(end) - int(start)) / 1000.0)
    steps = {}
    for output, (command_hash, seconds) in sorted(runs.items()):
        named = steps.get(command_hash)
        if named is None or (kind(named[0]) == "other steps" and kind(output) != "other steps"):
            steps[command_hash] = (output, seconds)
    last = dict(steps.values())
    totals = collections.Counter()
    for output, seconds in last.items():
        totals[kind(output)] += seconds
    for name, seconds in totals.most_common():
        print(f"{seconds:8.0f} s  {name}")
    print(f"{sum(totals.values()):8.0f} s  in all, {len(last)} steps")
    print(f"slowest {args.top}:")
    for output, seconds in sorted(last.items(), key=lambda item: -item[1])[:args.top]:
        print(f"{seconds:8.1f} s  {output}")


if __name__ == "__main__":
    main()
