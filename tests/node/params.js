// Set the robot's mass_kg to VALUE with /virtual_robot/set_parameters, then read it back with
// /virtual_robot/get_parameters. Prints {set, get}, each {ok: true, values} or
// {ok: false, reason}. Whether set may succeed depends on the admin token in WS_URL.
'use strict';

const { ROSLIB, callService, connect, run } = require('./lib');

const PARAMETER_DOUBLE = 3;  // rcl_interfaces/msg/ParameterType

run(async (url, value) => {
  const ros = await connect(url);
  const setParameters = new ROSLIB.Service({
    ros: ros,
    name: '/virtual_robot/set_parameters',
    serviceType: 'rcl_interfaces/srv/SetParameters'
  });
  const getParameters = new ROSLIB.Service({
    ros: ros,
    name: '/virtual_robot/get_parameters',
    serviceType: 'rcl_interfaces/srv/GetParameters'
  });
  const set = await callService(setParameters, {
    parameters: [{ name: 'mass_kg', value: { type: PARAMETER_DOUBLE, double_value: Number(value) } }]
  }, 3000);
  const get = await callService(getParameters, { names: ['mass_kg'] }, 3000);
  return { set: set, get: get };
});
