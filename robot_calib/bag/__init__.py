"""Bags: MCAP files as `ros2 bag record -s mcap` (Jazzy) writes them; ROS-free.

`BagWriter` writes raw CDR messages with their receive times; `BagReader` reads them back
(also from a bag whose recorder was killed). `ros2_formats` holds the rosbag2 formats.
"""

from robot_calib.bag.mcap_reader import BagMessage, BagReader, TopicInfo
from robot_calib.bag.mcap_writer import BagWriter
from robot_calib.bag.ros2_formats import QosProfile, message_definition, type_description_hash

__all__ = [
    "BagMessage",
    "BagReader",
    "BagWriter",
    "QosProfile",
    "TopicInfo",
    "message_definition",
    "type_description_hash",
]
