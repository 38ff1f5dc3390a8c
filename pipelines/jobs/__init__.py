"""The offline jobs the command line calls, each a function over an options object or arguments.

- :mod:`.simulate`: truth and device into an MCAP log or arrays (``gyroemu simulate``);
- :mod:`.estimate`: a filter over a log, its estimate added to a copy (``gyroemu estimate``);
- :mod:`.allan`: Allan deviation fit and plot of a log (``gyroemu allan``);
- :mod:`.bench`: filters against truth over simulated cases and logs (``gyroemu bench``);
- :mod:`.campaign`: a bench over a campaign file's grid on Dask, rows in Parquet (``gyroemu bench --campaign``);
- :mod:`.generate`: a dataset of MCAP logs over a campaign file's grid on Dask (``gyroemu generate``);
- :mod:`.demo`: the main job on built-in defaults, an orchestrator of the others (``gyroemu demo``);
- :mod:`.identify`, :mod:`.twin`: a device fitted to recordings, and its twins held against them;
- :mod:`.info`: what a log holds, per device and per topic (``gyroemu info``);
- :mod:`.view`: a log served to the Foxglove app with play, pause and seek (``gyroemu view``);
- :mod:`.progress`: progress bars, by phase or by samples; :mod:`.disk_space`: the disk an output needs.
- :mod:`.inputs`: the files a job reads, which its outputs never write over; :mod:`.run_span`: how short
  a run may be.
"""
