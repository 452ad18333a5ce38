// Subscribe to /robot_description and read its URDF with roslibjs's own parser
// (ROSLIB.UrdfModel: what ros3djs's Urdf and UrdfClient draw from); print what it read: each
// link's visuals (geometry, pose, colour) and each joint (type, parent, child, origin).
'use strict';

const { ROSLIB, connect, record, run, waitFor } = require('./lib');

const LATCHED_WITHIN_MS = 2000;

function pose(origin) {
  const { position: p, orientation: q } = origin;
  return { xyz: [p.x, p.y, p.z], quaternion: [q.x, q.y, q.z, q.w] };
}

function geometry(shape) {
  const types = { [ROSLIB.URDF_CYLINDER]: 'cylinder', [ROSLIB.URDF_BOX]: 'box',
    [ROSLIB.URDF_SPHERE]: 'sphere', [ROSLIB.URDF_MESH]: 'mesh' };
  return { type: types[shape.type], radius: shape.radius, length: shape.length };
}

run(async (url) => {
  const ros = await connect(url);
  const descriptions = record(new ROSLIB.Topic({
    ros: ros,
    name: '/robot_description',
    messageType: 'std_msgs/msg/String'
  }));
  await waitFor(() => descriptions.length > 0, LATCHED_WITHIN_MS, '/robot_description');
  const model = new ROSLIB.UrdfModel({ string: descriptions[0].data });
  const links = {};
  for (const [name, link] of Object.entries(model.links)) {
    links[name] = link.visuals.map((visual) => ({
      geometry: geometry(visual.geometry),
      origin: pose(visual.origin),
      rgba: visual.material && visual.material.color
        ? [visual.material.color.r, visual.material.color.g, visual.material.color.b,
          visual.material.color.a] : null
    }));
  }
  const joints = {};
  for (const [name, joint] of Object.entries(model.joints)) {
    joints[name] = { type: joint.type, parent: joint.parent, child: joint.child,
      origin: pose(joint.origin) };
  }
  return { name: model.name, links, joints };
});
