"""What a run leaves behind: the result schema and Datasets (``results``) and crash-safe files
(``io``). Nothing is imported here."""
