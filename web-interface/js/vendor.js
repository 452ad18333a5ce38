// The third-party code, in one place: installed by npm from package-lock.json into
// web-interface/node_modules and served from there (classrooms are offline: no CDN).
//
// roslib and nipplejs are UMD builds loaded by <script> tags before the page's modules (any
// static server gives .js the right MIME type); uPlot is imported as an ES module.

export { default as uPlot } from '../node_modules/uplot/dist/uPlot.esm.js';

/** The roslibjs namespace (ROSLIB.Ros, Topic, Service...). */
export const ROSLIB = globalThis.ROSLIB;

/** The nipplejs namespace (nipplejs.create). */
export const nipplejs = globalThis.nipplejs;

/** What is missing, for the page's error message: [] when everything loaded. */
export function missingLibraries() {
  return [['roslib', ROSLIB], ['nipplejs', nipplejs]]
    .filter(([, lib]) => !lib).map(([name]) => name);
}
