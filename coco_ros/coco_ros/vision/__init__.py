"""Vision over ROS: recordings of ROS camera topics as the peers of coco_mr_vision's readers."""
