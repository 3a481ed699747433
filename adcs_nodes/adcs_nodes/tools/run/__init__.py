"""Running a scenario: the launcher, composed and live runs, the launch file."""
