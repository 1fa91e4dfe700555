"""Running the library: whole runs, evaluation, the command line, the demo, benchmarks, plots.

This layer orchestrates the others and nothing below imports it:

- `config`: `RunConfig`, everything a run does (the shipped recipe by default);
- `pipeline`: a whole run as one function (data -> adapter -> SAC -> export -> evaluation),
  and what one does with an export (`evaluate_export`, `transfer_arm`);
- `eval`: the evaluation protocol (cells of arm x controller, intervals, per-episode CSV);
  `report`: per-episode CSVs read back, paired and formatted (intervals: `dpc_mjx.stats`);
- `cli`: the `dpc-mjx` command; `demo`: `make demo` and `dpc-mjx variants`;
- `bench`: env vs physics throughput (`dpc-mjx bench`); `plots`: the run's figures.
"""
