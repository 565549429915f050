"""Who else is on the graph: ros_discovery_info read as `ros2 node list` reads it, so the
node can say when a second node with its full name appears (two /arm_sim nodes would share
one joint_states and the same commands without a word)."""
from cyclonedds.core import Policy
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from ..wire import messages as msg


class NameWatch:
    def __init__(self, participant, namespace: str, name: str, log):
        self.own = bytes(msg.gid(participant).data)
        self.full_name = (namespace, name)
        self.log = log
        self.reader = DataReader(
            participant, Topic(participant, "ros_discovery_info", msg.ParticipantEntitiesInfo),
            qos=msg.discovery_info_qos(Policy.History.KeepAll))
        self.others = set()            # gids of other participants with a node of our name

    def check(self) -> None:
        """Warn once for each other participant announcing a node of the same full name."""
        for info in self.reader.take(N=256):
            if not isinstance(info, msg.ParticipantEntitiesInfo):
                continue
            gid = bytes(info.gid.data)
            names = {(n.node_namespace, n.node_name) for n in info.node_entities_info_seq}
            if gid != self.own and self.full_name in names and gid not in self.others:
                self.others.add(gid)
                namespace, name = self.full_name
                self.log.warning(f"another node named {namespace.rstrip('/')}/{name} is on this "
                                 "domain: both publish joint_states and take the same commands; "
                                 "give one another name (-r __node:=NAME) or ROS_DOMAIN_ID")
