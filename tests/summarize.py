"""Sums the JUnit XML reports in a folder: one line per suite, the failed tests, and the closing
line 'N passed, N failed[, N skipped]'. Exits 1 if anything failed or a suite wrote no report."""
import glob
import os
import sys
import xml.etree.ElementTree as ET

EXPECTED = ["cpp.xml", "python.xml", "blender-3.4.xml", "blender-bpy.xml"]


def main(folder: str) -> int:
    passed = failed = skipped = 0
    ok = True
    listed = os.path.join(folder, "expected.txt")  # written by test.sh: one report per suite it ran
    expected = open(listed).read().split() if os.path.exists(listed) else EXPECTED
    for name in expected:
        path = os.path.join(folder, name)
        if not os.path.exists(path):
            print(f"{name[:-4]:>12}: no report (the suite did not run to the end)")
            ok = False
            continue
        try:
            root = ET.parse(path).getroot()
        except ET.ParseError:
            print(f"{name[:-4]:>12}: an unreadable report (the suite crashed while writing it)")
            ok = False
            continue
        cases = list(root.iter("testcase"))
        bad = [c for c in cases if c.find("failure") is not None or c.find("error") is not None]
        skip = [c for c in cases if c.find("skipped") is not None]
        passed += len(cases) - len(bad) - len(skip)
        failed += len(bad)
        skipped += len(skip)
        print(f"{name[:-4]:>12}: {len(cases) - len(bad) - len(skip)} passed, {len(bad)} failed, {len(skip)} skipped")
        for c in bad:
            print(f"{'':>14}FAILED {c.get('classname', '')}::{c.get('name')}")
        if not cases:
            ok = False
    print(f"{passed} passed, {failed} failed" + (f", {skipped} skipped" if skipped else ""))
    return 0 if ok and failed == 0 and passed > 0 else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else "build/test-results"))
