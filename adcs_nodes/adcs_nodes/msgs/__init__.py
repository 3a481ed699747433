"""Core sample <-> ROS message conversion, CDR codecs and message fields (the messages layer)."""
