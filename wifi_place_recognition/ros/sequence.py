"""Messages a publisher sent that a subscription never delivered."""


class PublisherGaps:
    """
    Count the gaps in a publisher's sequence numbers on one subscription.

    DDS numbers every message a publisher sends; a subscription callback
    that takes the message info sees them. A gap is messages that a newer
    one replaced in the subscription's queue, or (best effort) that were
    lost on the way. rclpy does not say which publisher sent a message, so
    gaps are counted only while one publisher is matched; the first message
    and a sequence that restarts (a new publisher) count nothing.
    """

    def __init__(self):
        self.last = None

    def missed(self, subscription, info):
        """Return how many messages are missing before this one."""
        sequence = info['publication_sequence_number']
        last, self.last = self.last, sequence
        if last is None or sequence is None or sequence <= last + 1 or \
                subscription.get_publisher_count() != 1:
            return 0
        return sequence - last - 1
