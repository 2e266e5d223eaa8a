"""The grasp stage: a taxonomy of grasp pre-shapes closed on each catalogue object (per side), and their refit to
any hand shape per frame."""
