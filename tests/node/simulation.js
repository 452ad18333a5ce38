// simulation_interfaces and turtlesim's names through roslibjs (tests/test_simulation_interfaces_clients.py).
//
// Calls /get_simulator_features, /set_entity_state (a teleport), /get_entity_state,
// /robot/teleport_absolute, /spawn_entity (unsupported in a world of one robot) and /spawn,
// as a course's browser code would (ROSLIB.Service with the standard's types), and prints
// every answer: {features, set, state, teleport, stateAfterTeleport, spawn, turtleSpawn}.
'use strict';

const { ROSLIB, callService, connect, run } = require('./lib');

const ANSWER_MS = 5000;

run(async (url) => {
  const ros = await connect(url);
  const service = (name, type) => new ROSLIB.Service({ ros, name, serviceType: type });
  const pkg = 'simulation_interfaces/srv/';
  const out = {};
  out.features = await callService(service('/get_simulator_features', pkg + 'GetSimulatorFeatures'),
    {}, ANSWER_MS);
  out.set = await callService(service('/set_entity_state', pkg + 'SetEntityState'), {
    entity: 'robot',
    state: {
      header: { frame_id: 'map' },
      pose: { position: { x: 1.25, y: -0.5, z: 0 }, orientation: { x: 0, y: 0, z: 0, w: 1 } }
    }
  }, ANSWER_MS);
  out.state = await callService(service('/get_entity_state', pkg + 'GetEntityState'),
    { entity: 'robot' }, ANSWER_MS);
  out.teleport = await callService(service('/robot/teleport_absolute',
    'turtlesim/srv/TeleportAbsolute'), { x: -1.0, y: 1.0, theta: 1.5 }, ANSWER_MS);
  out.stateAfterTeleport = await callService(service('/get_entity_state', pkg + 'GetEntityState'),
    { entity: 'robot' }, ANSWER_MS);
  out.spawn = await callService(service('/spawn_entity', pkg + 'SpawnEntity'), {
    name: 'second', entity_resource: { uri: 'websim://robot' }
  }, ANSWER_MS);
  out.turtleSpawn = await callService(service('/spawn', 'turtlesim/srv/Spawn'),
    { x: 1, y: 1, theta: 0, name: '' }, ANSWER_MS);
  ros.close();
  return out;
});
