// ROS message shapes in and out, as plain functions: no DOM, no connection.
//
// Units are ROS's (m, s, rad); pixels exist only in view.js. JSON from rosbridge writes every
// non-finite float as null, so every number read here may be null.

/** visualization_msgs/Marker type and action codes. */
export const MARKER = Object.freeze({
  CUBE: 1, CYLINDER: 3, LINE_LIST: 5, ADD: 0, DELETE: 2, DELETEALL: 3,
});

/** rcl_interfaces/msg/ParameterValue's field per ParameterType (robot.json has the codes). */
const PARAMETER_FIELDS = Object.freeze({
  BOOL: ['bool_value', (v) => typeof v === 'boolean'],
  INTEGER: ['integer_value', Number.isInteger],
  DOUBLE: ['double_value', (v) => typeof v === 'number'],
  STRING: ['string_value', (v) => typeof v === 'string'],
});

/** builtin_interfaces/Time as seconds (a float), or null without one. */
export function stampSeconds(stamp) {
  if (!stamp || !Number.isFinite(stamp.sec)) return null;
  return stamp.sec + (stamp.nanosec || 0) * 1e-9;
}

/** Yaw (rad) of a geometry_msgs/Quaternion: rotation about z. */
export function yawFromQuaternion(q) {
  const { x = 0, y = 0, z = 0, w = 1 } = q || {};
  return Math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z));
}

/**
 * nav_msgs/Odometry -> {x, y, theta (rad), v (m/s), omega (rad/s), stampS, frame}, or null
 * when the pose is not finite.
 */
export function poseFromOdometry(msg) {
  const position = msg?.pose?.pose?.position;
  if (!position || !Number.isFinite(position.x) || !Number.isFinite(position.y)) return null;
  const twist = msg.twist?.twist ?? {};
  return {
    x: position.x,
    y: position.y,
    theta: yawFromQuaternion(msg.pose.pose.orientation),
    v: Number.isFinite(twist.linear?.x) ? twist.linear.x : 0,
    omega: Number.isFinite(twist.angular?.z) ? twist.angular.z : 0,
    stampS: stampSeconds(msg.header?.stamp),
    frame: msg.header?.frame_id ?? '',
  };
}

/** geometry_msgs/msg/Twist for a planar robot: linear.x (m/s), angular.z (rad/s). */
export function twist(linearMps, angularRps) {
  return {
    linear: { x: linearMps, y: 0, z: 0 },
    angular: { x: 0, y: 0, z: angularRps },
  };
}

/** {linear, angular} (m/s, rad/s) of a Twist message; missing or null fields read 0. */
export function twistValues(msg) {
  const linear = msg?.linear?.x;
  const angular = msg?.angular?.z;
  return {
    linear: Number.isFinite(linear) ? linear : 0,
    angular: Number.isFinite(angular) ? angular : 0,
  };
}

/**
 * The pose {x, y, yaw} of `child` in `parent` from a tf2_msgs/TFMessage, or null when the
 * message does not hold that transform (only direct transforms are looked up).
 */
export function transformFromTf(msg, parent, child) {
  for (const t of msg?.transforms ?? []) {
    if (t.header?.frame_id === parent && t.child_frame_id === child) {
      const { translation, rotation } = t.transform;
      return { x: translation.x || 0, y: translation.y || 0, yaw: yawFromQuaternion(rotation) };
    }
  }
  return null;
}

/**
 * The returns of a sensor_msgs/LaserScan as points in the laser frame (m): a Float32Array of
 * x, y pairs. A beam has no return when its range is null (JSON's non-finite), below
 * range_min (cannot be measured), or at or beyond range_max (the course platform's "nothing
 * within range"; REP 117 says +inf, which JSON carries as null).
 */
export function scanPoints(scan) {
  const ranges = scan?.ranges ?? [];
  const points = new Float32Array(ranges.length * 2);
  const { angle_min: angleMin = 0, angle_increment: increment = 0 } = scan ?? {};
  const rangeMin = Number.isFinite(scan?.range_min) ? scan.range_min : 0;
  const rangeMax = Number.isFinite(scan?.range_max) ? scan.range_max : Infinity;
  let n = 0;
  for (let i = 0; i < ranges.length; i += 1) {
    const r = ranges[i];
    if (r === null || !Number.isFinite(r) || r < rangeMin || r >= rangeMax) continue;
    const angle = angleMin + i * increment;
    points[n] = r * Math.cos(angle);
    points[n + 1] = r * Math.sin(angle);
    n += 2;
  }
  return points.subarray(0, n);
}

/** `pose` {x, y, yaw} composed with `offset` {x, y, yaw} given in pose's frame. */
export function composePose(pose, offset) {
  const c = Math.cos(pose.yaw);
  const s = Math.sin(pose.yaw);
  return {
    x: pose.x + c * offset.x - s * offset.y,
    y: pose.y + s * offset.x + c * offset.y,
    yaw: pose.yaw + offset.yaw,
  };
}

/**
 * Applies a visualization_msgs/MarkerArray to `markers` (a Map of "ns/id" -> shape) and
 * returns it: LINE_LIST markers become wall segments, CYLINDER markers discs, CUBE markers
 * boxes (filled rectangles, their yaw kept); DELETE and
 * DELETEALL remove. Other marker types are ignored. Shapes are in the marker's frame (the
 * world publishes in map), marker pose applied.
 */
export function applyMarkerArray(markers, msg) {
  for (const marker of msg?.markers ?? []) {
    const key = `${marker.ns ?? ''}/${marker.id ?? 0}`;
    if (marker.action === MARKER.DELETEALL) {
      markers.clear();
    } else if (marker.action === MARKER.DELETE) {
      markers.delete(key);
    } else if (marker.type === MARKER.LINE_LIST) {
      const pose = markerPose(marker);
      const points = (marker.points ?? []).map((p) => composePose(pose, { x: p.x, y: p.y, yaw: 0 }));
      const segments = [];
      for (let i = 0; i + 1 < points.length; i += 2) {
        segments.push([points[i].x, points[i].y, points[i + 1].x, points[i + 1].y]);
      }
      markers.set(key, { kind: 'segments', segments, width: marker.scale?.x || 0.02 });
    } else if (marker.type === MARKER.CYLINDER) {
      const pose = markerPose(marker);
      markers.set(key, { kind: 'disc', x: pose.x, y: pose.y, radius: (marker.scale?.x || 0) / 2 });
    } else if (marker.type === MARKER.CUBE) {
      const pose = markerPose(marker);
      const [w, h] = [(marker.scale?.x || 0) / 2, (marker.scale?.y || 0) / 2];
      const corners = [[-w, -h], [w, -h], [w, h], [-w, h]].map(([x, y]) => {
        const corner = composePose(pose, { x, y, yaw: 0 });
        return [corner.x, corner.y];
      });
      markers.set(key, { kind: 'polygon', corners });
    }
  }
  return markers;
}

/**
 * The robots of a world (its /world_robots visualization_msgs/MarkerArray: a CYLINDER each,
 * its text the robot's name) -> [{name, x, y, yaw (rad), radius (m)}] in the map frame, but
 * the robot named `self` (the page's own) and any whose pose is not finite.
 */
export function robotsFromMarkers(msg, self = null) {
  const robots = [];
  for (const marker of msg?.markers ?? []) {
    if (marker.type !== MARKER.CYLINDER || marker.action === MARKER.DELETE) continue;
    const name = typeof marker.text === 'string' ? marker.text : '';
    const position = marker.pose?.position;
    if (name === self || !Number.isFinite(position?.x) || !Number.isFinite(position?.y)) continue;
    const pose = markerPose(marker);
    robots.push({ name, x: pose.x, y: pose.y, yaw: pose.yaw, radius: (marker.scale?.x || 0) / 2 });
  }
  return robots;
}

function markerPose(marker) {
  const position = marker.pose?.position ?? {};
  return { x: position.x || 0, y: position.y || 0, yaw: yawFromQuaternion(marker.pose?.orientation) };
}

/** Axis-aligned bounds {minX, minY, maxX, maxY} of the shapes in `markers`, or null if none. */
export function markerBounds(markers) {
  let minX = Infinity;
  let minY = Infinity;
  let maxX = -Infinity;
  let maxY = -Infinity;
  const grow = (x, y, r = 0) => {
    minX = Math.min(minX, x - r);
    minY = Math.min(minY, y - r);
    maxX = Math.max(maxX, x + r);
    maxY = Math.max(maxY, y + r);
  };
  for (const shape of markers.values()) {
    if (shape.kind === 'segments') {
      for (const [x1, y1, x2, y2] of shape.segments) {
        grow(x1, y1);
        grow(x2, y2);
      }
    } else if (shape.kind === 'polygon') {
      for (const [x, y] of shape.corners) grow(x, y);
    } else {
      grow(shape.x, shape.y, shape.radius);
    }
  }
  return Number.isFinite(minX) ? { minX, minY, maxX, maxY } : null;
}

/** The ParameterType name (BOOL, DOUBLE...) of `code` in `types` (robot.json's parameter_types). */
function parameterKind(types, code) {
  return Object.keys(types).find((kind) => types[kind] === code);
}

/**
 * rcl_interfaces/msg/ParameterValue of type `code` holding `value`; `types` maps ParameterType
 * names to codes (robot.json's parameter_types). Throws a TypeError when `value` does not fit.
 */
export function parameterValue(types, code, value) {
  const [field, fits] = PARAMETER_FIELDS[parameterKind(types, code)] ?? [];
  if (!field) throw new TypeError(`no ParameterValue of type ${code}`);
  if (!fits(value)) {
    throw new TypeError(`${JSON.stringify(value)} is not a ${parameterKind(types, code)}`);
  }
  return { type: code, [field]: value };
}

/** The JS value a ParameterValue holds (by its type code in `types`), or undefined when not set. */
export function valueOfParameter(types, msg) {
  const [field] = PARAMETER_FIELDS[parameterKind(types, msg?.type)] ?? [];
  return field ? msg[field] : undefined;
}
