"""Live transport over Eclipse Zenoh, and the jobs that move samples live.

- :mod:`.zenoh_io`: sessions and their options, keys, attachments, the paced publisher, one teardown;
- :mod:`.stream`: a simulated device streamed on its sample clock (``gyroemu stream``);
- :mod:`.record`: streams recorded into MCAP (``gyroemu record``), and the router (``gyroemu router``);
- :mod:`.replay`: an MCAP log republished on its own clock (``gyroemu replay``);
- :mod:`.live_estimate`: a filter run on a live stream (``gyroemu stream --estimate``);
- :mod:`.foxglove_view`: a live 3D view on a Foxglove WebSocket (``--foxglove``, ``gyroemu view``).
"""
