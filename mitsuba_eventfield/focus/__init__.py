"""Refocus and depth: focus measures (``measures``, a leaf), align-and-add refocus and focal stacks
(``refocus``) and depth from focus (``depth``)."""
