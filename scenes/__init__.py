"""Synthetic patients with known truth, seen by a simulated depth camera: the parametric Chen torso
(`synthetic`), realistic MakeHuman bodies (`makehuman`) and their scenes (`realistic`), before/after
ptosis pairs (`realistic_pairs`), depth rendering and noise (`rendering`). The tests, the benchmarks
and `breastplan scan-synth` use them; the stages themselves never do."""
