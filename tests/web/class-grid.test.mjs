// What a card says (web-interface/js/class-grid.js): clients, payload, the pause badge, links.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  byName, capitalized, clientsText, pauseBadge, payloadText, robotPageUrl,
} from '../../web-interface/js/class-grid.js';
import { parseStatus } from '../../web-interface/js/class-state.js';
import { robot } from './robot.mjs';

test('clients: the students\' (the owner\'s page among them), not the instructor\'s', () => {
  assert.equal(clientsText(null), '–');
  assert.equal(clientsText(parseStatus({})), '–');
  const status = (clients, owners, instructors) => parseStatus({
    client_count: clients, admin_count: owners + instructors, owner_count: owners,
    instructor_count: instructors,
  });
  assert.equal(clientsText(status(1, 0, 1)), '0', 'the dashboard alone');
  assert.equal(clientsText(status(3, 1, 1)), '2 (owner)', 'the owner is a student, no admin');
  assert.equal(clientsText(status(4, 2, 1)), '3 (owner ×2)');
  assert.equal(clientsText(parseStatus({ client_count: 3, admin_count: 1 })), '2',
    'an older server: the admins left out');
});

test('payload ×1 and ×2 by robot.json\'s defaults, another one by its mass', () => {
  const { mass_kg: mass, inertia_kg_m2: inertia } = robot.robot;
  const status = (m, i) => parseStatus({ mass_kg: m, inertia_kg_m2: i });
  assert.equal(payloadText(status(mass, inertia), robot), 'payload ×1');
  assert.equal(payloadText(status(2 * mass, 2 * inertia), robot), 'payload ×2');
  assert.equal(payloadText(status(3, inertia), robot), 'payload 3.00 kg');
  assert.equal(payloadText(null, robot), 'payload –');
});

test('the pause badge tells the instructor\'s pause from an idle robot', () => {
  assert.equal(pauseBadge(parseStatus({ paused: true, held: true })), 'paused');
  assert.equal(pauseBadge(parseStatus({ paused: true, held: false })), 'idle');
  assert.equal(pauseBadge(parseStatus({ paused: false })), '');
  assert.equal(pauseBadge(null), '');
});

test('a robot\'s page link and button labels', () => {
  assert.equal(robotPageUrl('/robots/', 'robot05'), '/robots/robot05/');
  assert.equal(robotPageUrl('/robots/', 'a b'), '/robots/a%20b/');
  assert.equal(capitalized('dynamic'), 'Dynamic');
});

test('cards are in name order, numbers as numbers, case aside', () => {
  const names = ['robot10', 'bob', 'robot2', 'Alice', 'robot01'];
  assert.deepEqual(names.sort(byName), ['Alice', 'bob', 'robot01', 'robot2', 'robot10']);
});
