"""Input safety: reading files that nobody vouches for without letting them exhaust the machine.

* :mod:`lvcore.safety.limits`: every resource limit in one place (file sizes, JSON depth, mesh and design
  sizes, memory budgets) and the readers that enforce them (regular files only, size checked before reading);
* :mod:`lvcore.safety.headers`: the sizes a mesh or array file declares in its header, checked against those
  limits before a reader allocates anything;
* :mod:`lvcore.safety.isolation`: a parser run in a memory- and time-limited child process, so a hostile file
  that crashes or exhausts it costs an error message, not the server.

Importing this package imports none of them.
"""
