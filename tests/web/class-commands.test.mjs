// The instructor's commands (web-interface/js/class-commands.js) through a real Connection on
// a fake roslibjs: each call under the robot's namespace with the right request, refusals with
// the server's reason, payloads from robot.json's defaults, and the "for all" fan-out.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import { Connection, ServiceCallError } from '../../web-interface/js/connection.js';
import {
  ClassCommands, FAN_OUT_CONCURRENCY, fanOutSummary, forAll, modeChoices, otherMode,
  PARAMETERS, payloadDefaults, payloadFactor, payloadValues,
} from '../../web-interface/js/class-commands.js';
import { parseStatus } from '../../web-interface/js/class-state.js';
import { parameterSpec } from '../../web-interface/js/robot.js';
import { fakeRoslib } from './fake-roslib.mjs';
import { robot } from './robot.mjs';

/** ClassCommands on a connected fake socket; `answer(call)` answers each service call. */
function connected(answer) {
  const { ROSLIB, sockets } = fakeRoslib();
  const connection = new Connection(ROSLIB, { url: 'ws://h:9090/', token: 't', tokenUrl: 'ws://h:9090/' });
  connection.connect();
  sockets[0].emit('connection');
  const calls = [];
  sockets[0].on('call', (call) => {
    calls.push({ name: call.name, request: call.request });
    answer(call);
  });
  return { commands: new ClassCommands(connection, robot), calls };
}

test('reset and pause go to the robot\'s own services under its namespace', async () => {
  const { commands, calls } = connected((call) => call.ok(
    call.name.endsWith('/websim/pause') ? { paused: call.request.paused } : {}));
  await commands.reset('alice');
  assert.deepEqual(await commands.pause('bob', true), { paused: true });
  await commands.pause('bob', false);
  assert.deepEqual(calls, [
    { name: `/alice${robot.services.reset.name}`, request: {} },
    { name: '/bob/websim/pause', request: { paused: true } },
    { name: '/bob/websim/pause', request: { paused: false } },
  ]);
});

test('every robot\'s status comes at once from /websim/class_status on the root', async () => {
  const { commands, calls } = connected((call) => call.ok({ robots: [
    { name: 'robot01', mode: 'kinematic' }, { name: 'robot02', mode: 'dynamic' }] }));
  const statuses = await commands.classStatus();
  assert.deepEqual([...statuses.keys()], ['robot01', 'robot02']);
  assert.equal(parseStatus(statuses.get('robot02')).mode, 'dynamic');
  assert.deepEqual(calls, [{ name: '/websim/class_status', request: {} }]);
});

test('the robot list comes from /websim/robots on the root', async () => {
  const { commands, calls } = connected((call) => call.ok({ names: ['robot01', 'robot02'] }));
  assert.deepEqual(await commands.robots(), ['robot01', 'robot02']);
  assert.deepEqual(calls, [{ name: '/websim/robots', request: {} }]);
});

test('mode and payload are set_parameters requests of robot.json\'s types', async () => {
  const { commands, calls } = connected((call) => call.ok({
    results: call.request.parameters.map(() => ({ successful: true, reason: '' })),
  }));
  await commands.setMode('alice', 'dynamic');
  await commands.setPayload('bob', 2);
  const { DOUBLE, STRING } = robot.parameter_types;
  const mass = parameterSpec(robot, 'mass_kg').default;
  const inertia = parameterSpec(robot, 'inertia_kg_m2').default;
  assert.deepEqual(calls, [
    { name: `/alice${robot.services.set_parameters.name}`, request: { parameters: [
      { name: 'mode', value: { type: STRING, string_value: 'dynamic' } }] } },
    { name: `/bob${robot.services.set_parameters.name}`, request: { parameters: [
      { name: 'mass_kg', value: { type: DOUBLE, double_value: 2 * mass } },
      { name: 'inertia_kg_m2', value: { type: DOUBLE, double_value: 2 * inertia } }] } },
  ]);
});

test('a refused call rejects with the server\'s reason', async () => {
  const refusing = connected((call) => call.fail(`${call.name} needs admin rights`));
  await assert.rejects(refusing.commands.reset('alice'),
    (error) => error instanceof ServiceCallError
      && error.message === `/alice${robot.services.reset.name} needs admin rights`);
  const rejecting = connected((call) => call.ok({ results: [
    { successful: false, reason: 'mode must be one of kinematic, dynamic' }] }));
  await assert.rejects(rejecting.commands.setMode('bob', 'dynamic'),
    /^Error: mode: mode must be one of kinematic, dynamic$/);
});

test('payloads are robot.json\'s mass and inertia times 1 or 2, and read back from a status', () => {
  const defaults = payloadDefaults(robot);
  assert.deepEqual(defaults, { massKg: robot.robot.mass_kg, inertiaKgM2: robot.robot.inertia_kg_m2 });
  assert.deepEqual(payloadValues(robot, 1),
    { [PARAMETERS.mass]: defaults.massKg, [PARAMETERS.inertia]: defaults.inertiaKgM2 });
  const status = (massKg, inertiaKgM2) => parseStatus({ mass_kg: massKg, inertia_kg_m2: inertiaKgM2 });
  assert.equal(payloadFactor(status(defaults.massKg, defaults.inertiaKgM2), robot), 1);
  assert.equal(payloadFactor(status(2 * defaults.massKg, 2 * defaults.inertiaKgM2), robot), 2);
  assert.equal(payloadFactor(status(2 * defaults.massKg, defaults.inertiaKgM2), robot), null);
  assert.equal(payloadFactor(status(null, null), robot), undefined);
  assert.equal(payloadFactor(null, robot), undefined);
});

test('the mode toggle goes round robot.json\'s choices', () => {
  const [first, second] = modeChoices(robot);
  assert.deepEqual(modeChoices(robot), parameterSpec(robot, 'mode').choices);
  assert.equal(otherMode(robot, first), second);
  assert.equal(otherMode(robot, second), first);
});

test('for all: every robot once, at most a few at a time, each failure kept with its name',
  async () => {
    const names = Array.from({ length: 20 }, (_, i) => `robot${i}`);
    let running = 0;
    let most = 0;
    const results = await forAll(names, async (name) => {
      running += 1;
      most = Math.max(most, running);
      await new Promise((resolve) => { setImmediate(resolve); });
      running -= 1;
      if (name === 'robot3') throw new Error('no robot named robot3');
      return name.toUpperCase();
    });
    assert.equal(most, FAN_OUT_CONCURRENCY);
    assert.deepEqual(results.map((r) => r.name), names, 'in the names\' order');
    assert.deepEqual(results[0], { name: 'robot0', ok: true, value: 'ROBOT0' });
    assert.equal(results[3].ok, false);
    assert.equal(results[3].error.message, 'no robot named robot3');
    assert.equal(fanOutSummary('paused', results), 'paused 19 of 20; 1 refused (see their cards)');
    assert.equal(fanOutSummary('reset', results.filter((r) => r.ok)), 'reset 19 robots');
    assert.deepEqual(await forAll([], async () => 1), []);
  });

test('for all sends one call per robot over the one connection', async () => {
  const { commands, calls } = connected((call) => call.ok({ paused: true }));
  const names = ['a', 'b', 'c'];
  const results = await forAll(names, (name) => commands.pause(name, true));
  assert.ok(results.every((r) => r.ok));
  assert.deepEqual(calls.map((c) => c.name).sort(), ['/a/websim/pause', '/b/websim/pause',
    '/c/websim/pause']);
});
