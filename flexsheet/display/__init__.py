"""The display layer above the generic runtime: what a flexsheet launch file adds (the ``twin``, ``scene`` and
``display_calib`` sections, :mod:`flexsheet.display.launch`)."""
