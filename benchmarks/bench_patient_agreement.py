"""Can the registration of two chests (`ingest.follow_up.register`) tell two women apart? The share of the chest two
scans show that lies within 5 mm once registered (`agreement`), for two visits of one woman whose cup changed
(bench_follow_up's women, both sides, the second visit from the same camera and from another) and for pairs of
different women (those visits and four more MakeHuman bodies, left sides). A follow-up whose earlier case agrees
under `ingest.follow_up.MIN_AGREEMENT` is refused as another patient's; beyond it, only her patient ID can tell.

Run:  .venv/bin/python benchmarks/bench_patient_agreement.py     (about 2 minutes)
"""
from __future__ import annotations

import itertools
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from bench_follow_up import FIRST, SECOND, WOMEN, visit  # noqa: E402

from breastplan.ingest.follow_up import MIN_AGREEMENT, register  # noqa: E402
from breastplan.scenes.makehuman import BodyOptions  # noqa: E402

OTHERS = {"slim, A-pose": BodyOptions(cup=0.5, weight=0.3, pose="a-pose"),
          "average, arms down": BodyOptions(cup=0.6, weight=0.5, pose="arms-down"),
          "heavy, hands on hips": BodyOptions(cup=0.7, weight=0.9, pose="hands-on-hips"),
          "muscular, arms down": BodyOptions(cup=0.4, weight=0.4, muscle=0.9, pose="arms-down")}


def main() -> None:
    scans = {}
    for woman, (base, lo, hi) in WOMEN.items():
        scans[(woman, "then")] = visit(BodyOptions(cup=lo, **base), FIRST, 1)[0]
        for how, camera in SECOND.items():
            scans[(woman, how)] = visit(BodyOptions(cup=hi, **base), camera, 2)[0]
    for name, body in OTHERS.items():
        scans[(name, "then")] = visit(body, SECOND["another camera"], 3)[0]
    same = [register(scans[(w, "then")][s], scans[(w, how)][s]).agreement
            for w in WOMEN for how in SECOND for s in ("left", "right")]
    other = [register(scans[a]["left"], scans[b]["left"]).agreement
             for a, b in itertools.permutations(scans, 2) if a[0] != b[0]]
    print(f"one woman's two visits: agreement {min(same):.2f}–{max(same):.2f} ({len(same)} pairs)")
    print(f"two women: agreement {min(other):.2f}–{max(other):.2f} ({len(other)} pairs); "
          f"{sum(a >= MIN_AGREEMENT for a in other)} of them at or above {MIN_AGREEMENT:.0%}, so accepted")
    print(json.dumps({"benchmark": "bench_patient_agreement", "same_woman": [min(same), max(same)],
                      "other_women": [min(other), max(other)], "other_accepted": sum(a >= MIN_AGREEMENT for a in other),
                      "other_pairs": len(other)}))


if __name__ == "__main__":
    main()
