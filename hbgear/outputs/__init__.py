"""Files a run writes: atomic CSV/JSON/figure writes (:mod:`.io`)."""
