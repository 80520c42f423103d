"""Files: the one writer, the rules for files a user names, the key paths of a
model file, its named constants, and pictures."""
