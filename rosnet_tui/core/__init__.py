"""Core logic: checks, advisor, configuration writers and address sync. Imports no Textual."""
