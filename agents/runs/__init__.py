"""A training run's files and what is made from them: the run folder's layout and lock, the episode log, checkpoints
(saved, resumed, loaded as policies), the resumable state stored without pickle, the finished run's result, and a
checkpoint exported as ONNX or rendered as a video."""
