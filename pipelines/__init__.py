"""gyroemu's data side: formats, live transport, estimation, the jobs, and the command line.

Each folder is a layer; arrows point down only:

- :mod:`.cli` (the command line: parses arguments, calls a job, prints);
- :mod:`.jobs` (simulate, estimate, allan, bench, demo) and :mod:`.transport` (zenoh sessions; stream,
  record, replay, the live filter);
- :mod:`.estimation` (the MEKF, its peers, the filter protocol, metrics);
- :mod:`.formats` (CDR messages, the channel vocabulary, MCAP records and logs, ROS 2 keys, importers).

:mod:`.mcap_io` keeps the names of the former single MCAP module importable.
"""

__all__: list[str] = []
