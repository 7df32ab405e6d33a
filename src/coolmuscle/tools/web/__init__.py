"""``--web``: the dashboard's host tools (:mod:`.dashboard`: banks and traces for the page)
and the option's launcher (:mod:`.run`: the transport, a script played for the page).
The page itself is :mod:`coolmuscle.frontends.web`."""
