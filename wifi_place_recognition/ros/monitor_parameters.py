"""localization_monitor's interface: its topics, and its parameters."""

from dataclasses import replace
import math

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from rcl_interfaces.msg import ParameterDescriptor
from std_msgs.msg import Bool, String

from ..core.coverage import OFF_SURVEY_BELOW
from ..core.witness_params import MAY_BE_ZERO, WitnessParams
from . import node_interface
from .node_interface import float_range

SUMMARY = """
Watches the robot's localiser (e.g. AMCL) with WiFi as an independent
witness: compares its pose with classifier_node's fused pose and scan
positions, taking both sides' uncertainty and the survey's coverage into
account, and says on the latched ~/status, ~/localization_ok and on
/diagnostics whether the localiser agrees with WiFi, WiFi cannot tell
(nothing to compare) or the localiser is lost. With initial_pose_on_lost
it re-seeds the localiser on initialpose with the fused pose: at start-up
while the localiser has no pose, and when it is judged lost (also on
another floor's map).
"""

#: (role, name, type, what) of every topic the node uses.
TOPICS = (
    ('subscribes', '{localizer_topic}', PoseWithCovarianceStamped,
     'the localiser\'s pose (localizer_topic; AMCL: amcl_pose), in its '
     'frame; reliable'),
    ('subscribes', '{fused_topic}', PoseWithCovarianceStamped,
     'classifier_node\'s fused pose (fused_topic), the WiFi witness'),
    ('subscribes', '{place_topic}', DiagnosticArray,
     'classifier_node\'s answers (place_topic): each scan\'s own position, '
     'sigma and coverage probability'),
    ('publishes', '~/status', String,
     'the state: agrees (WiFi compared and found no disagreement, the '
     'localiser is not lost), disagrees (evidence against the localiser '
     'gathering, not yet lost), cannot_tell (nothing to compare: no fused '
     'pose or scan yet, the fused pose too wide, scans off the survey, the '
     'localiser silent), lost, or waiting (no localiser pose yet); latched '
     '(transient local), once per change'),
    ('publishes', '~/localization_ok', Bool,
     'the verdict: true while the localiser is not known to be lost '
     '(agrees, disagrees or cannot_tell), false when lost or before its '
     'first pose; '
     'latched (transient local), once per change'),
    ('publishes', '/diagnostics', DiagnosticArray,
     'the status every second and at once on a change of state (OK agrees, '
     'WARN disagrees, cannot tell or no localiser pose yet, ERROR lost): '
     'agreement '
     '(sigma), distance, for how long, score, bad localiser messages'),
    ('publishes', 'initialpose', PoseWithCovarianceStamped,
     'with initial_pose_on_lost: the fused pose and its covariance, at '
     'start-up and when the localiser is lost'),
)

_D = WitnessParams()


def _positive(name, description, default, high, unit=''):
    return (name, default, ParameterDescriptor(
        description=description + unit,
        floating_point_range=float_range(0.0, high)))


#: (name, default, descriptor) of every parameter, in declaration order.
PARAMETERS = (
    ('model_path', '', ParameterDescriptor(
        description='the model classifier_node runs (its survey: where the '
                    'scans can testify); empty: the shipped UJIIndoorLoc '
                    'model; set it while running when classifier_node\'s '
                    'changes (a file that does not load is refused, the '
                    'running model goes on)')),
    ('localizer_topic', 'amcl_pose', ParameterDescriptor(
        description='the localiser\'s PoseWithCovarianceStamped topic',
        read_only=True)),
    ('fused_topic', 'classifier_node/pose', ParameterDescriptor(
        description='classifier_node\'s ~/pose', read_only=True)),
    ('place_topic', 'classifier_node/place', ParameterDescriptor(
        description='classifier_node\'s ~/place', read_only=True)),
    ('frame_id', 'map', ParameterDescriptor(
        description='classifier_node\'s frame_id (may contain {building} and '
                    '{floor}); a localiser pose in a frame it cannot make '
                    'is refused')),
    ('initial_pose_on_lost', False, ParameterDescriptor(
        description='send the fused pose on initialpose at start-up (no '
                    'localiser pose yet) and when the localiser is lost, '
                    'once the fused pose is sure (sure_sd, sure_yaw_deg, '
                    'sure_s; at start-up startup_sure_s), not while most '
                    'of the last 5 scans do not testify')),
    _positive('agree_sigmas', 'a judgement this many standard deviations '
              'apart adds no evidence; farther adds, nearer takes away',
              _D.agree_sigmas, 100.0),
    _positive('alarm', 'evidence (sum of sigmas beyond agree_sigmas) at '
              'which the localiser is lost', _D.alarm, 1e4),
    _positive('floor_sd', 'metres added on each axis to both covariances '
              '(what neither knows)', _D.floor_sd, 100.0),
    _positive('scan_floor_sd', 'the same for a scan\'s own position (m)',
              _D.scan_floor_sd, 100.0),
    _positive('max_scan_sigma', 'scans with a larger sigma (m) are off the '
              'survey unless their coverage probability is '
              f'{OFF_SURVEY_BELOW:g} or more: no evidence, nor is the fused '
              'pose while the recent scans are so', _D.max_scan_sigma,
              1000.0),
    _positive('yaw_floor_deg', 'degrees added to both yaw deviations',
              round(math.degrees(_D.yaw_floor_sd), 6), 180.0),
    _positive('sure_sd', 'a fused pose this sure (m, largest standard '
              'deviation) may seed the localiser', _D.sure_sd, 100.0),
    _positive('sure_yaw_deg', 'and its yaw this sure (degrees)',
              round(math.degrees(_D.sure_yaw_sd), 6), 180.0),
    _positive('sure_s', 'and the scans of the last so many seconds lie on '
              'average within sure_sd of its track (a pose dragged by '
              'scans off the survey, not yet back, does not; 0: not '
              'asked)', _D.sure_s, 3600.0),
    _positive('startup_sure_s', 'a start-up seed only from a fused pose '
              'sure so many seconds without a break (a young filter\'s '
              'covariance narrows before its heading is right; re-seeds do '
              'not wait; 0: not asked)', _D.startup_sure_s, 3600.0),
    _positive('max_age', 'seconds after which a pose is old: the '
              'localiser\'s newest is silent (not compared), and WiFi '
              'cannot tell once its last comparison is this much older '
              'than the newest stamp', _D.max_age, 3600.0),
    _positive('silent_m', 'metres the fused pose moves with the localiser '
              'silent before that counts as lost', _D.silent_m, 1000.0),
    _positive('holdoff', 'seconds between two seeds', _D.holdoff, 3600.0),
)

#: Parameter name -> WitnessParams field (degrees -> radians).
WITNESS_FIELDS = {'agree_sigmas': 'agree_sigmas', 'alarm': 'alarm',
                  'floor_sd': 'floor_sd', 'scan_floor_sd': 'scan_floor_sd',
                  'max_scan_sigma': 'max_scan_sigma',
                  'yaw_floor_deg': 'yaw_floor_sd', 'sure_sd': 'sure_sd',
                  'sure_yaw_deg': 'sure_yaw_sd', 'sure_s': 'sure_s',
                  'startup_sure_s': 'startup_sure_s',
                  'max_age': 'max_age',
                  'silent_m': 'silent_m', 'holdoff': 'holdoff'}


def declare(node):
    """Declare every parameter on ``node``; return {name: value}."""
    return node_interface.declare(node, PARAMETERS)


def witness_params(values, base=None):
    """
    Return WitnessParams from parameter ``values`` (others from ``base``).

    Raises ValueError naming a refused value and the rule it breaks, in
    the parameters' terms (names, degrees).
    """
    base = base or WitnessParams()
    changes = {}
    for name, value in values.items():
        if name in WITNESS_FIELDS:
            field = WITNESS_FIELDS[name]
            off = field in MAY_BE_ZERO
            if not (value > 0 or off and value == 0):   # the ranges take 0
                raise ValueError(f'{name} = {value!r}: expected a number '
                                 f'{">= 0" if off else "> 0"}')
            changes[field] = math.radians(value) if name.endswith('_deg') \
                else float(value)
    alarm = changes.get('alarm', base.alarm)
    if alarm <= base.max_step:
        raise ValueError(
            f'alarm = {alarm!r} must be above {base.max_step:g}: one '
            f'judgement adds at most {base.max_step:g} to the evidence (its '
            f'sigmas beyond agree_sigmas, capped), and one judgement must '
            f'never alarm')
    return replace(base, **changes)
