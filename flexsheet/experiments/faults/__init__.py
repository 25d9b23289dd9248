"""``flexsheet experiment faults --out DIR [--quick]``: each hostile input and fault against the
runtime, the links and the twins, counted (:mod:`.experiment`)."""
