"""The run report and Table I: what a recorded run's bag says, read after the run.

Modules: :mod:`.table1` (the Fig. 9 metrics of Table I and the paper's targets), :mod:`.report` (the launch's
``report:``, writing ``OUT/report.md`` and ``OUT/summary.json``), :mod:`.report_analysis` (the bag read into
Table I, felt and latency figures), :mod:`.report_head`, :mod:`.report_softness`, :mod:`.report_timing` (their
sections), :mod:`.report_verdicts`, :mod:`.report_text`, :mod:`.report_charts` (verdicts, text, charts). The
experiments of :mod:`flexsheet.experiments` use the same metrics in-process.
"""
