// Run the browser's heading PID (web-interface/js/pid.js) over a trace given as JSON on argv
// and print its outputs, so tests/test_pid_and_compare.py can hold it equal to physics/pid.py.
// Usage: node pid_trace.mjs '{"gains": {...}, "setpoint": rad, "dt": s, "headings": [rad...]}'
import { INITIAL_STATE, makeGains, pidStep } from '../../web-interface/js/pid.js';

const { gains, setpoint, dt, headings } = JSON.parse(process.argv[2]);
const made = makeGains(gains);
let state = INITIAL_STATE;
const outputs = [];
for (const heading of headings) {
  const step = pidStep(made, state, setpoint, heading, dt);
  state = step.state;
  outputs.push({ output: step.output, error: step.error, integral: state.integral });
}
process.stdout.write(JSON.stringify(outputs));
