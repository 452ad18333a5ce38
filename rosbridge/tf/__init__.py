"""tf2_web_republisher on the bridge: a TF buffer of /tf and /tf_static, republished per client."""
