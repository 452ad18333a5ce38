// Print what ros.getTopics reports: {topics: [...], types: [...]}.
'use strict';

const { connect, run, waitFor } = require('./lib');

run(async (url) => {
  const ros = await connect(url);
  let result = null;
  ros.getTopics(
    (topics) => { result = topics; },
    (error) => { result = { error: error }; });
  await waitFor(() => result, 3000, 'the answer of ros.getTopics');
  if (result.error !== undefined) {
    throw new Error(`ros.getTopics failed: ${result.error}`);
  }
  return result;
});
