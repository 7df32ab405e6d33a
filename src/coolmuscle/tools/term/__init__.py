"""A motor from the user's terminal: ``coolmuscle term`` (:mod:`.terminal`) and ``coolmuscle
upload`` (:mod:`.upload`), both through :mod:`coolmuscle.client` only."""
