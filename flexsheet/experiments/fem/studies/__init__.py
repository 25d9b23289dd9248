"""The reference studies of ``flexsheet experiment fem``, one family a module: convergence (with the penalty
and skin studies), fold (its check and the tip-refined sequence), mirror, material, held-out azimuth,
and the linear mesh study."""
