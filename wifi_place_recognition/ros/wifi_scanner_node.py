"""
``wifi_scanner_node``: the robot's WiFi interface as ``wifi/scan`` messages.

Every ``period`` seconds a worker thread reads a scan from the first working
source of ``sources`` (``iw`` triggers a scan, ``iw_dump`` reads the
kernel's cached results, ``nmcli`` asks NetworkManager; see
:mod:`..data.wifi_sources`), drops readings older than ``max_age`` and
publishes a ``sensor_msgs/JointState`` (name = BSSID, position = RSSI dBm,
frame_id = interface). The scan commands run off the executor, so
parameters and the 1 Hz status on ``/diagnostics`` stay responsive while a
command hangs (up to its timeout). An ``interface`` missing from
``/sys/class/net`` stops the start-up (exit 1, naming the interfaces there);
no wireless interface (``interface`` empty), no permission or a missing tool
gives an ERROR status with the reason, and it keeps retrying.
"""

from collections import Counter
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState

from ..data.wifi_sources import (drop_stale, interface_problem, SOURCES,
                                 SourceError, SourceRunner,
                                 wireless_interfaces)
from .node_interface import declare
from .runner import names_the_node, run
from .scanner_parameters import PARAMETERS

THROTTLE_S = 30.0


class WifiScannerNode(Node):
    """Publish scans of one wireless interface at a fixed period."""

    @names_the_node
    def __init__(self):
        super().__init__('wifi_scanner_node')
        values = declare(self, PARAMETERS)
        self.interface = values['interface']
        self.period = values['period']
        self.sources = list(values['sources'])
        self.max_age = values['max_age']
        problem = self.interface and interface_problem(self.interface)
        if problem:
            raise ValueError(problem)
        unknown = [s for s in self.sources if s not in SOURCES]
        if unknown or not self.sources:
            raise ValueError(f'unknown scan sources {unknown}; use any of '
                             f'{sorted(SOURCES)}')
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.runner = SourceRunner(timeout=min(self.period * 5, 30.0))
        self.pub = self.create_publisher(JointState, 'wifi/scan',
                                         qos_profile_sensor_data)
        self.diag_pub = self.create_publisher(DiagnosticArray,
                                              '/diagnostics', 10)
        self.counts = Counter(scans_published=0, stale_readings=0,
                              failed_scans=0)
        self._lock = threading.Lock()
        self._result = (DiagnosticStatus.WARN, 'no scan yet', '')
        self._running_since = None
        self._stop = threading.Event()
        self.create_timer(1.0, self._publish_status)
        self._worker = threading.Thread(target=self._scan_loop,
                                        name='wifi_scan', daemon=True)
        self._worker.start()

    def _apply_parameters(self, params):
        for p in params:
            if p.name == 'max_age':
                self.max_age = p.value

    # the worker thread ----------------------------------------------------
    def _scan_loop(self):
        due = time.monotonic()
        while not self._stop.wait(max(0.0, due - time.monotonic())):
            due = max(due + self.period, time.monotonic())
            self._scan_once()

    def _scan_once(self):
        iface = self.interface or next(iter(wireless_interfaces()), '')
        stamp = self.get_clock().now().to_msg()
        started = time.monotonic()
        with self._lock:
            self._running_since = started
        try:
            if not iface:
                raise SourceError('no wireless interface found')
            source, readings = self.runner.scan(self.sources, iface)
        except SourceError as exc:
            if self._stop.is_set():
                return      # cancelled: the node is shutting down
            self._finish(DiagnosticStatus.ERROR, f'no scan: {exc}', iface,
                         failed_scans=1)
            self.get_logger().error(f'no scan: {exc}',
                                    throttle_duration_sec=THROTTLE_S)
            return
        max_age = self.max_age or self.period + time.monotonic() - started
        readings, stale = drop_stale(readings, max_age)
        old = f' ({stale} older than {max_age:.1f} s dropped)' if stale \
            else ''
        if not readings:
            self._finish(DiagnosticStatus.WARN,
                         f'{source}: no AP in range{old}', iface,
                         stale_readings=stale)
            return
        msg = JointState(name=[r.bssid for r in readings],
                         position=[r.dbm for r in readings])
        msg.header.stamp = stamp
        msg.header.frame_id = iface
        self.pub.publish(msg)
        self._finish(DiagnosticStatus.OK,
                     f'{len(readings)} APs from {source}{old}', iface,
                     scans_published=1, stale_readings=stale)

    def _finish(self, level, message, iface, **counts):
        with self._lock:
            self.counts.update(counts)
            self._result = (level, message, iface)
            self._running_since = None

    def destroy_node(self):
        """Stop the worker (killing a running scan command), then the node."""
        self._stop.set()
        self.runner.cancel()
        self._worker.join()
        super().destroy_node()

    # the executor ---------------------------------------------------------
    def _publish_status(self):
        with self._lock:
            level, message, iface = self._result
            counts = dict(self.counts)
            since = self._running_since
        running = time.monotonic() - since if since is not None else 0.0
        out = DiagnosticArray()
        out.header.stamp = self.get_clock().now().to_msg()
        out.status = [DiagnosticStatus(
            level=level, name=f'{self.get_name()}: scanner', message=message,
            hardware_id=iface or 'none',
            values=[KeyValue(key=k, value=str(v)) for k, v in counts.items()]
            + [KeyValue(key='scan_running_s', value=f'{running:.1f}'),
               KeyValue(key='max_age_s', value=f'{self.max_age:g}'),
               KeyValue(key='sources', value=','.join(self.sources))])]
        self.diag_pub.publish(out)


def main(args=None):
    """Run the scanner until SIGINT/SIGTERM; exit 1 on bad parameters."""
    return run(WifiScannerNode, args)


if __name__ == '__main__':
    # As the executable: --help starts nothing (stop signals are caught
    # only from here, after the imports; the installed executable, earlier)
    from wifi_place_recognition.ros.executables import wifi_scanner_node as _run
    sys.exit(_run())
