"""grbl's reference sender (``conform send``): the job as grbl reads it (job.py), the two
documented streaming methods (stream.py) and the command's hook (command.py)."""
