"""Flying identified models in closed loop: evolved PID waypoint control and the LQ tracker."""
