# The console scripts are installed to lib/coco_ros (where `ros2 run coco_ros <name>` finds them): put
# them on PATH too, so the README's commands work bare after `source install/setup.bash`.
_colcon_prepend_unique_value PATH "$COLCON_CURRENT_PREFIX/lib/coco_ros"
