// The course's roslibjs 1.4.1 rosapi calls against websim: ros.getTopics, getNodes,
// getNodeDetails, getTopicsForType, getServices, getParams, getMessageDetails (decoded with
// decodeTypeDefs), getServiceRequestDetails, and ROSLIB.Param get/set/delete, each with a
// callback and a failedCallback. Prints one JSON object: per call, which of the two ran
// ({callback: [...args]} or {failed: reason}). Run by tests/conformance/test_rosapi.py as
// `node rosapi.js WS_URL`; whether set may succeed depends on the token in WS_URL.
'use strict';

const { ROSLIB, connect, run, waitFor } = require('../../node/lib');

const ANSWER_TIMEOUT_MS = 5000;

// Calls `start(callback, failedCallback)`; resolves with which one ran and its arguments.
function outcome(start, what) {
  let answer = null;
  start((...args) => { answer = { callback: args }; },
    (reason) => { answer = { failed: reason }; });
  return waitFor(() => answer, ANSWER_TIMEOUT_MS, what);
}

run(async (url) => {
  const ros = await connect(url);
  const mass = new ROSLIB.Param({ ros, name: '/virtual_robot:mass_kg' });
  const missing = new ROSLIB.Param({ ros, name: '/virtual_robot:no_such_param' });
  const result = {};
  result.topics = await outcome((ok, failed) => ros.getTopics(ok, failed), 'getTopics');
  result.nodes = await outcome((ok, failed) => ros.getNodes(ok, failed), 'getNodes');
  result.nodeDetails = await outcome(
    (ok, failed) => ros.getNodeDetails('/virtual_robot', ok, failed), 'getNodeDetails');
  result.odomTopics = await outcome(
    (ok, failed) => ros.getTopicsForType('nav_msgs/msg/Odometry', ok, failed),
    'getTopicsForType');
  result.services = await outcome((ok, failed) => ros.getServices(ok, failed), 'getServices');
  result.params = await outcome((ok, failed) => ros.getParams(ok, failed), 'getParams');
  const details = await outcome(
    (ok, failed) => ros.getMessageDetails('geometry_msgs/Twist', ok, failed),
    'getMessageDetails');
  result.twistDetails = details;
  result.twistDecoded = details.callback ? ros.decodeTypeDefs(details.callback[0]) : null;
  result.resetRequest = await outcome(
    (ok, failed) => ros.getServiceRequestDetails('std_srvs/srv/Empty', ok, failed),
    'getServiceRequestDetails');
  result.getMass = await outcome((ok, failed) => mass.get(ok, failed), 'Param.get');
  result.getMissing = await outcome((ok, failed) => missing.get(ok, failed), 'Param.get');
  result.setMass = await outcome((ok, failed) => mass.set(2.5, ok, failed), 'Param.set');
  result.getMassAfter = await outcome((ok, failed) => mass.get(ok, failed), 'Param.get');
  result.deleteMass = await outcome((ok, failed) => mass.delete(ok, failed), 'Param.delete');
  return result;
});
