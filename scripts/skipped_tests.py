#!/usr/bin/env python3
"""Prints how many tests ctest skipped and why, from its JUnit report (ctest --output-junit).

Usage: skipped_tests.py REPORT.xml

The reason of a skip is the test's own line: a Google Test's message after "Skipped" (e.g. the
shared data it did not find), or a script's line starting with "skip:" (exit code 77). Skips with
the same reason are counted together, with the first few tests named.

A build with RECOG_TEST_PER_BINARY runs each gtest binary as one ctest test, which writes its own
report to gtest-reports/<module>_<name>.xml beside REPORT.xml: the cases of those reports are
counted instead of their binary.
"""
import collections
import os
import sys
import xml.etree.ElementTree as ElementTree


def skip_reason(testcase):
    lines = (testcase.findtext("system-out") or "").splitlines()
    for i, line in enumerate(lines):
        if line.endswith(": Skipped") and i + 1 < len(lines) and lines[i + 1].strip():
            return lines[i + 1].strip()
        if line.startswith("skip:"):
            return line[len("skip:"):].strip()
    skipped = testcase.find("skipped")
    return skipped.get("message", "no reason given") if skipped is not None else "no reason given"


def gtest_cases(report):
    """(name, skip reason or None) of each case in a Google Test XML report."""
    for case in ElementTree.parse(report).getroot().iter("testcase"):
        name = f"{case.get('classname')}.{case.get('name')}"
        skipped = case.find("skipped")
        if case.get("result") == "skipped" or skipped is not None:
            message = skipped.get("message", "") if skipped is not None else ""
            # "path:line\nreason": the reason is the message's last line.
            yield name, (message.strip().splitlines() or ["no reason given"])[-1].strip()
        else:
            yield name, None


def ctest_cases(report):
    """(name, skip reason or None) of each test ctest ran, a binary's cases in its place."""
    reports = os.path.join(os.path.dirname(os.path.abspath(report)), "gtest-reports")
    for case in ElementTree.parse(report).getroot().iter("testcase"):
        name = case.get("name")
        binary_report = os.path.join(reports, name.replace("/", "_") + ".xml")
        if "." not in name and os.path.exists(binary_report):
            yield from ((f"{name}.{case_name}", reason)
                        for case_name, reason in gtest_cases(binary_report))
        elif case.get("status") == "notrun" and case.find("skipped") is not None:
            yield name, skip_reason(case)
        else:
            yield name, None


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    total = 0
    reasons = collections.OrderedDict()
    for name, reason in ctest_cases(sys.argv[1]):
        total += 1
        if reason is not None:
            reasons.setdefault(reason, []).append(name)
    skipped = sum(len(names) for names in reasons.values())
    print(f"{skipped} of {total} tests skipped" + (":" if skipped else ""))
    for reason, names in reasons.items():
        shown = ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
        print(f"  {len(names)} x {reason}\n      ({shown})")


if __name__ == "__main__":
    main()
