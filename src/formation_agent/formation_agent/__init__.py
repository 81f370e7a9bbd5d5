"""One agent of the event-triggered formation controller: the ROS-free ETA-1/ETA-2 core and its node."""
