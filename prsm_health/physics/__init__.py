"""PRSM physics core (papers 000, 001, 002, 004): no ROS, no filters."""
