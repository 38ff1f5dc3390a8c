"""File and message formats: what gyroemu's data look like on disk and on the wire.

- :mod:`.messages`: CDR codecs of the ROS 2 message types, on whole arrays;
- :mod:`.channels`: the channel vocabulary (topics, roles, types, frame ids) and the one encoding of
  samples into message fields;
- :mod:`.mcap_records`: MCAP records (bulk writer, scanner, message walk), below
  :mod:`.mcap_log`: gyroemu logs (recordings, device logs, metadata, ``write_mcap``, ``read_mcap``);
- :mod:`.tf_messages`: ``tf2_msgs/msg/TFMessage`` CDR codec, on whole arrays;
- :mod:`.frames`: the tf tree (frames, mounting, the /tf rate) and absolute start times;
- :mod:`.imu_covariance`: the per-sample variances ``/imu`` carries (REP 145);
- :mod:`.ros2_keys`: ROS 2 on rmw_zenoh (REP-2011 type hashes, key expressions, liveliness tokens);
- :mod:`.importers`: other formats (BROAD's HDF5 trials) into the MCAP contract.
"""
