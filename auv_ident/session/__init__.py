"""Session layer: what one message does, without ROS. Takes arrays and stamps; reads
ROS-shaped messages by duck typing only.

- session.py: IdentSession, the identifier's per-message logic (array API and message adapters),
  composed of the parts below;
- guarded_filter.py: GuardedFilter, one filter's per-message update (the session's running
  filter and the 'auto' choice's chosen filter alike);
- status.py: the counters and health of a session, and its /diagnostics values;
- screening.py: rejection policy, frame-id and plausibility rules (pure functions);
- guard.py: divergence guard, reset rule, health rule; the Event/LastGood/Health records;
- settings.py: parameter checks (ParameterError) and the choice lists;
- messages.py: nav_msgs/Odometry and sensor_msgs/JointState read into arrays, frame algebra;
- raw_messages.py: an input map's raw-sensor messages (IMU, DVL, pressure, pose) as NED/FRD
  core.filter.raw.RawMeasurement records, and the map's RawSensorConfig;
- raw_session.py: RawSession, the live node's per-message logic for a map with raw sensors
  (each message one step of core.filter.raw.RawSensorFilter);
- auto_choice.py: coefficients ['auto', ...], the set chosen live from the first auto_window s;
- record.py: the accepted messages as the arrays the batch methods take (pairing, exact hold);
- estimate_file.py: the estimate JSON file; warning_limiter.py: rate limit of warnings.
"""
